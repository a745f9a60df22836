// Wrong-pair detection from prior-independent evidence (issue 5; beyond the paper, whose §4.11
// "Failure analysis" leaves "structured subset selection over the matches or the view graph"
// unexplored). A verified pair is wrong when its two-view relative pose disagrees with the rest
// of the match graph: the robust global solution computed without it (or outvoting it)
// contradicts its relative rotation or its translation direction. No pose prior and no ground
// truth enter; §4.11 explains why: scoring matches against a coarse prior would reject correct
// correspondences exactly when the prior is bad.
#pragma once

#include <vector>
#include "core/named_enum.h"
#include "core/options.h"

#include "bootstrap/rotation_averaging.h"
#include "bootstrap/translation_averaging.h"
#include "bootstrap/view_graph.h"

namespace raytime {

struct WrongPairOptions {
  // A pair is wrong when its rotation-averaging residual exceeds this (degrees). The default is
  // the paper's 5° direction-edge gate (§4.8), which already separates sound from symmetric-
  // structure edges.
  double wrong_rotation_deg = 5.0;
  // ... or when the angle between its measured translation direction and the one between the
  // averaged centres exceeds this (degrees). Repeated structure often yields a plausible
  // rotation with a displaced translation.
  double wrong_direction_deg = 15.0;
  // A triplet of pairs is cycle-consistent when the composed rotation R_ki^T R_kj R_ji is within
  // this angle of the identity (degrees); reported per pair as support evidence.
  double cycle_tolerance_deg = 5.0;
  // Rounds of solve-on-kept-pairs / re-score-all-pairs; stops early when the verdicts settle.
  int wrong_pair_rounds = 3;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("wrong_rotation_deg", wrong_rotation_deg,
      "Wrong pair above this rotation-averaging residual, degrees (§4.8: 5°)", Positive(),
      AtMost(180));
    v("wrong_direction_deg", wrong_direction_deg,
      "Wrong pair above this translation-direction residual, degrees", Positive(), AtMost(180));
    v("cycle_tolerance_deg", cycle_tolerance_deg,
      "Triplet cycle consistency tolerance, degrees (reported evidence)", Positive(), AtMost(180));
    v("wrong_pair_rounds", wrong_pair_rounds, "Rounds of solve-on-kept-pairs / re-score-all-pairs",
      Positive(), AtMost(1000));
  }
};

enum class PairVerdict { kKept, kWrong, kUnusable };
constexpr std::array<EnumName<PairVerdict>, 3> EnumNames(PairVerdict) {
  return {{{PairVerdict::kKept, "kept"},
           {PairVerdict::kWrong, "wrong"},
           {PairVerdict::kUnusable, "unusable"}}};
}
inline const char* PairVerdictName(PairVerdict verdict) { return NameOf(verdict); }

struct PairScore {
  PairVerdict verdict = PairVerdict::kUnusable;
  // Against the last round's solution (NaN when an image of the pair is not registered or the
  // pair has no translation direction).
  double rotation_residual_deg = 0.0;
  double direction_residual_deg = 0.0;
  // Triplets through this pair whose other two pairs are usable, and how many close within
  // cycle_tolerance_deg.
  int cycle_triplets = 0;
  int cycle_consistent = 0;
  // max(rotation residual / wrong_rotation_deg, direction residual / wrong_direction_deg):
  // above 1 means wrong; a ranking score for precision/recall curves.
  double score = 0.0;
};

// Relative rotations and world-frame translation directions of graph edges, for the averaging
// kernels. `rotations` (camera-to-world, per node) orient the directions; directions are only
// built for edges usable for translation whose index is in `edge_indices`.
std::vector<RelativeRotation> RotationEdges(const std::vector<ViewGraphEdge>& edges,
                                            const std::vector<int>& edge_indices);
std::vector<RelativeDirection> DirectionEdges(const std::vector<ViewGraphEdge>& edges,
                                              const std::vector<int>& edge_indices,
                                              const std::vector<Eigen::Matrix3d>& rotations);

struct PairClassification {
  std::vector<PairScore> scores;  // one per input edge
  std::vector<int> kept;          // indices of the kept edges (usable and not wrong)
  int num_wrong = 0;
  int num_unusable = 0;
  int rounds = 0;
  // The solution of the last round, on the kept pairs: rotations, then centres from the kept
  // pairs' directions that pass `direction_gate_deg`.
  RotationAveragingResult rotations;
  TranslationAveragingResult translations;
};

// Classifies every edge. `direction_gate_deg` is the paper's 5° rotation-residual gate on
// direction edges (§4.8), applied inside each round before translation averaging.
PairClassification ClassifyPairs(int num_nodes, const std::vector<ViewGraphEdge>& edges,
                                 const WrongPairOptions& options,
                                 const RotationAveragingOptions& rotation_options,
                                 const TranslationAveragingOptions& translation_options,
                                 double direction_gate_deg);

}  // namespace raytime

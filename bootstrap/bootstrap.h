// Prior-free poses from the match graph (SPEC §4; paper §4.8 "Refinement without an external
// prior"): relative poses per verified pair, the pre-solve fragility flag, wrong-pair detection,
// rotation averaging, then centres by LUD translation averaging or the look-at seed, and whether
// the graph can support that estimate at all (graph_support.h).
//
// The bootstrap never reads a pose prior or ground truth; gauge fits onto a prior live in
// prior_repair.h and take the prior as an explicit argument.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>
#include "core/options.h"

#include "bootstrap/focal_search.h"
#include "bootstrap/graph_support.h"
#include "bootstrap/look_at_seed.h"
#include "bootstrap/relative_pose.h"
#include "bootstrap/rotation_averaging.h"
#include "bootstrap/translation_averaging.h"
#include "bootstrap/view_graph.h"
#include "bootstrap/wrong_pairs.h"
#include "core/features.h"
#include "core/types.h"
#include "core/warnings.h"

namespace raytime {

struct BootstrapOptions {
  // Centres: "lud" (translation averaging over the two-view directions) or "look_at" (each
  // camera at look_at_distance behind its optical axis; assumes a commonly faced object).
  std::string positions = "lud";
  // Only pairs whose rotation-averaging residual is at most this contribute a translation
  // direction (paper §4.8: the 5° gate removes symmetric-structure outliers), degrees.
  double direction_gate_deg = 5.0;
  // Solve the final poses on the pairs the wrong-pair detector keeps; false solves on every
  // usable pair (the paper's recipe) and only reports the verdicts.
  bool filter_pairs = true;
  // Pre-solve fragility flag: mean pairwise rotation-averaging residual over all usable pairs
  // above this is fragile (paper §4.8: the band separates fragile scenes at ~10°), degrees.
  double fragility_threshold_deg = 10.0;
  // Unknown intrinsics: search a shared focal per camera, principal point at the image centre,
  // no distortion (paper §4.8).
  bool focal_search = false;

  RelativePoseOptions relative_pose;
  RotationAveragingOptions rotation_averaging;
  TranslationAveragingOptions translation_averaging;
  LookAtSeedOptions look_at;
  FocalSearchOptions focal;
  WrongPairOptions wrong_pairs;
  GraphSupportOptions graph_support;

  // Flat keys (YAML key = field name; the sub-structs' names are unique).
  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("positions", positions, "Centres by LUD translation averaging or the look-at seed (§4.8)",
      OneOf({"lud", "look_at"}));
    v("direction_gate_deg", direction_gate_deg,
      "Pairs above this rotation-averaging residual give no direction, degrees (§4.8: 5°)",
      Positive(), AtMost(180));
    v("filter_pairs", filter_pairs,
      "Solve the final poses on the pairs the wrong-pair detector keeps");
    v("fragility_threshold_deg", fragility_threshold_deg,
      "Fragile above this mean pairwise rotation-averaging residual, degrees (§4.8: ~10°)",
      Positive(), AtMost(180));
    v("focal_search", focal_search, "Unknown intrinsics: search a shared focal per camera (§4.8)");
    relative_pose.VisitFields(v);
    rotation_averaging.VisitFields(v);
    translation_averaging.VisitFields(v);
    look_at.VisitFields(v);
    focal.VisitFields(v);
    wrong_pairs.VisitFields(v);
    graph_support.VisitFields(v);
  }
  void CheckRelations(const Requirement& require) const { focal.CheckRelations(require); }
};

struct FragilityReport {
  double mean_residual_deg = 0.0;  // the statistic (paper §4.8)
  double median_residual_deg = 0.0;
  int num_pairs = 0;
  double threshold_deg = 0.0;
  bool fragile = false;
};

struct BootstrapResult {
  std::vector<ViewGraphEdge> edges;       // one per verified pair with inliers
  std::vector<CameraIntrinsics> cameras;  // intrinsics used (searched when focal_search)
  std::vector<FocalSearchResult> focal_searches;
  int num_pairs_input = 0;

  FragilityReport fragility;
  // Per edge: residual of the all-pairs rotation averaging the fragility flag is computed from
  // (NaN for unusable pairs or pairs outside the largest component).
  std::vector<double> fragility_residual_deg;
  PairClassification pairs;  // verdicts and scores, one per edge

  // The final solve (on the kept pairs when filter_pairs).
  RotationAveragingResult rotations;
  TranslationAveragingResult translations;  // positions "lud"
  LookAtSeedResult look_at;                 // positions "look_at"
  // Per image: camera-to-world rotation and centre. An image in the rotation component has a
  // rotation and so a pose; its centre is estimated by translation averaging, or filled by the
  // look-at rule (positions "lud": outside the translation component, placed around the point
  // nearest the optical axes of the estimated ones; all of them when no direction survived), or
  // is the requested look-at seed (positions "look_at").
  std::vector<Eigen::Matrix3d> world_from_cam;
  std::vector<Eigen::Vector3d> centres;
  std::vector<bool> rotation_registered;  // in the rotation component: has a pose
  std::vector<bool> position_estimated;   // centre from translation averaging
  int num_rotations_registered = 0;
  int num_positions_estimated = 0;
  int num_positions_filled = 0;
  // Whether the graph supports the estimate (too little parallax, too many filled centres).
  GraphSupport support;

  double relative_pose_seconds = 0.0;
  double global_seconds = 0.0;
};

// Global poses from an estimated view graph (fills every field from `fragility` on).
void SolveGlobalPoses(int num_images, const BootstrapOptions& options, BootstrapResult* result);

// The whole bootstrap from features and verified matches. Throws InputError on inconsistent input
// or options.
BootstrapResult RunBootstrap(const ImageSet& images, const std::vector<ImageFeatures>& features,
                             const std::vector<PairMatches>& matches,
                             const BootstrapOptions& options);

// "weak" when the graph cannot support the estimate, "fragile" when the fragility flag fires,
// "fragile and weak" for both, else "not fragile".
const char* FragilityVerdict(const BootstrapResult& result);

// "weak_bootstrap" when the graph cannot support the estimate (issue 13): the reasons in words,
// the images whose pose is not estimated from the graph (no rotation, or a centre filled by the
// look-at fallback) and GraphSupportJson as details. Empty otherwise.
Warnings BootstrapWarnings(const ImageSet& images, const BootstrapResult& result);

// What the bootstrap stage reports (its summary.json entry; field names are the keys).
struct BootstrapSummary {
  struct Fragility {  // the pre-solve flag (paper §4.8) and the graph's support of the estimate
    double mean_residual_deg = 0.0;
    double median_residual_deg = 0.0;
    int num_pairs = 0;
    double threshold_deg = 0.0;
    bool fragile = false;
    std::string verdict;                    // FragilityVerdict
    std::vector<std::string> weak_reasons;  // GraphSupport::reasons
  };
  struct Pairs {  // the wrong-pair detector's verdicts over the usable pairs
    int kept = 0;
    int wrong = 0;
    int unusable = 0;
    int rounds = 0;
  };
  struct RotationAveraging {
    int num_edges = 0;
    int l1_iterations = 0;
    int irls_iterations = 0;
    bool converged = false;
    double mean_residual_deg = 0.0;
    double median_residual_deg = 0.0;
  };
  struct TranslationAveraging {
    int num_edges = 0;
    int num_registered = 0;
    int iterations = 0;
    bool converged = false;
    double mean_residual_deg = 0.0;
    double median_residual_deg = 0.0;
  };
  struct FocalSearch {  // one per camera searched
    int camera = 0;
    double focal_px = 0.0;
    int num_pairs = 0;
    std::vector<double> candidates_px;
    std::vector<int> inliers;
  };
  struct Seconds {
    double relative_poses = 0.0;
    double global = 0.0;
  };
  // The pre-solve flag that decides the configuration (paper §5, SPEC §3 "Deployment").
  struct Guardrails {
    bool fragile = false;
    double fragility_deg = 0.0;
    bool weak_bootstrap = false;
  };

  int num_images = 0;
  int num_pairs = 0;
  int num_usable_pairs = 0;
  int num_pure_rotation_pairs = 0;
  int num_rotations_registered = 0;
  int num_positions_estimated = 0;
  int num_positions_filled = 0;
  std::string positions;  // BootstrapOptions::positions
  Fragility fragility;
  nlohmann::json graph_support;  // GraphSupportJson
  Pairs pairs;
  RotationAveraging rotation_averaging;
  TranslationAveraging translation_averaging;
  std::vector<FocalSearch> focal_search;
  Seconds seconds;
  Guardrails guardrails;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::Fragility, mean_residual_deg,
                                   median_residual_deg, num_pairs, threshold_deg, fragile, verdict,
                                   weak_reasons)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::Pairs, kept, wrong, unusable, rounds)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::RotationAveraging, num_edges, l1_iterations,
                                   irls_iterations, converged, mean_residual_deg,
                                   median_residual_deg)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::TranslationAveraging, num_edges,
                                   num_registered, iterations, converged, mean_residual_deg,
                                   median_residual_deg)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::FocalSearch, camera, focal_px, num_pairs,
                                   candidates_px, inliers)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::Seconds, relative_poses, global)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary::Guardrails, fragile, fragility_deg,
                                   weak_bootstrap)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(BootstrapSummary, num_images, num_pairs, num_usable_pairs,
                                   num_pure_rotation_pairs, num_rotations_registered,
                                   num_positions_estimated, num_positions_filled, positions,
                                   fragility, graph_support, pairs, rotation_averaging,
                                   translation_averaging, focal_search, seconds, guardrails)

BootstrapSummary SummarizeBootstrap(int num_images, const BootstrapOptions& options,
                                    const BootstrapResult& result);

// The poses of the images with a rotation, keyed by image name.
PoseSet BootstrapPoses(const ImageSet& images, const BootstrapResult& result);

}  // namespace raytime

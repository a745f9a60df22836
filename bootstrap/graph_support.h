// Whether the view graph can support the bootstrap's estimate (issue 13, "Honest results"). The
// fragility flag (paper §4.8) measures how much the usable pairs disagree about rotations; it
// cannot see a graph that agrees because it says little: a slow sweep whose pairs are mostly
// near-pure rotations carries no translation directions, so translation averaging places few
// cameras and the look-at rule (paper §4.8 "Refinement without an external prior", which assumes
// a commonly faced object) fills in the rest. Such a bootstrap is "weak": its rotations may be
// sound, its centres are not estimated from the images. Computed from the graph alone, never from
// a prior or ground truth.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bootstrap/view_graph.h"
#include "core/options.h"

namespace raytime {

struct GraphSupportOptions {
  // Weak when more than this share of the usable pairs (valid + near-pure rotation) are near-pure
  // rotations, which constrain rotations but carry no translation direction.
  double max_pure_rotation_share = 0.5;
  // Weak when more than this share of the images with a rotation got their centre from the
  // look-at fallback instead of translation averaging (positions "lud").
  double max_filled_share = 0.2;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("max_pure_rotation_share", max_pure_rotation_share,
      "Weak graph above this share of near-pure-rotation pairs among the usable pairs",
      NonNegative(), AtMost(1));
    v("max_filled_share", max_filled_share,
      "Weak graph above this share of images placed by the look-at fallback (positions lud)",
      NonNegative(), AtMost(1));
  }
};

// Which images have what: a pose needs a rotation; its centre comes from translation averaging
// ("estimated") or the look-at fallback ("filled"). With positions "look_at" every centre is the
// requested look-at seed: neither estimated nor filled.
struct PositionSources {
  int num_images = 0;
  int num_rotations_registered = 0;
  int num_positions_estimated = 0;
  int num_positions_filled = 0;
};

struct GraphSupport {
  int num_usable_pairs = 0;         // usable for rotation averaging
  int num_pure_rotation_pairs = 0;  // of those, near-pure rotations
  int num_direction_pairs = 0;      // of those, with a translation direction
  double pure_rotation_share = 0.0;
  // Median over the usable pairs of each pair's median parallax (degrees): how far the graph is
  // from a panorama, reported beside the shares.
  double median_parallax_deg = 0.0;
  PositionSources positions;
  double filled_share = 0.0;  // num_positions_filled / num_rotations_registered
  GraphSupportOptions thresholds;
  // Why the graph cannot support the estimate: "pure_rotation_share", "filled_share" (a rule's
  // share above its threshold). Empty for a graph that supports it.
  std::vector<std::string> reasons;
  bool weak = false;
};

// Throws std::invalid_argument on counts that do not add up.
GraphSupport AssessGraphSupport(const std::vector<ViewGraphEdge>& edges,
                                const PositionSources& positions,
                                const GraphSupportOptions& options);

// One sentence naming each reason with its number and threshold, e.g. "59% of the usable pairs
// are near-pure rotations (threshold 50%)"; empty when not weak.
std::string DescribeWeakness(const GraphSupport& support);

// Every number above with its threshold, for summaries and warning details.
nlohmann::json GraphSupportJson(const GraphSupport& support);

}  // namespace raytime

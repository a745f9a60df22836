#include "bootstrap/graph_support.h"

#include <cmath>
#include <stdexcept>

#include "core/statistics.h"

namespace raytime {
namespace {

double Share(int part, int whole) { return whole > 0 ? static_cast<double>(part) / whole : 0.0; }

std::string Percent(double share) { return std::to_string(std::lround(100.0 * share)) + "%"; }

}  // namespace

GraphSupport AssessGraphSupport(const std::vector<ViewGraphEdge>& edges,
                                const PositionSources& positions,
                                const GraphSupportOptions& options) {
  ValidateOptions(options, "graph support");
  if (positions.num_rotations_registered < 0 ||
      positions.num_rotations_registered > positions.num_images ||
      positions.num_positions_estimated < 0 || positions.num_positions_filled < 0 ||
      positions.num_positions_estimated + positions.num_positions_filled >
          positions.num_rotations_registered) {
    throw std::invalid_argument(
        "AssessGraphSupport: estimated and filled positions exceed the registered images");
  }
  GraphSupport support;
  support.positions = positions;
  support.thresholds = options;
  std::vector<double> parallax;
  for (const ViewGraphEdge& e : edges) {
    if (!e.UsableForRotation()) continue;
    ++support.num_usable_pairs;
    support.num_pure_rotation_pairs += e.status == PairStatus::kPureRotation;
    support.num_direction_pairs += e.UsableForTranslation();
    parallax.push_back(e.median_parallax_deg);
  }
  support.pure_rotation_share = Share(support.num_pure_rotation_pairs, support.num_usable_pairs);
  support.median_parallax_deg = FiniteUpperMedian(std::move(parallax));
  support.filled_share = Share(positions.num_positions_filled, positions.num_rotations_registered);
  if (support.pure_rotation_share > options.max_pure_rotation_share) {
    support.reasons.push_back("pure_rotation_share");
  }
  if (support.filled_share > options.max_filled_share) support.reasons.push_back("filled_share");
  support.weak = !support.reasons.empty();
  return support;
}

std::string DescribeWeakness(const GraphSupport& support) {
  std::string out;
  for (const std::string& reason : support.reasons) {
    if (!out.empty()) out += "; ";
    if (reason == "pure_rotation_share") {
      out += Percent(support.pure_rotation_share) + " of the usable pairs (" +
             std::to_string(support.num_pure_rotation_pairs) + " of " +
             std::to_string(support.num_usable_pairs) +
             ") are near-pure rotations with no translation direction (threshold " +
             Percent(support.thresholds.max_pure_rotation_share) + ")";
    } else if (reason == "filled_share") {
      out += Percent(support.filled_share) + " of the images with a rotation (" +
             std::to_string(support.positions.num_positions_filled) + " of " +
             std::to_string(support.positions.num_rotations_registered) +
             ") have a centre from the look-at fallback, not translation averaging (threshold " +
             Percent(support.thresholds.max_filled_share) + ")";
    }
  }
  return out;
}

nlohmann::json GraphSupportJson(const GraphSupport& support) {
  return {{"weak", support.weak},
          {"reasons", support.reasons},
          {"num_usable_pairs", support.num_usable_pairs},
          {"num_pure_rotation_pairs", support.num_pure_rotation_pairs},
          {"num_direction_pairs", support.num_direction_pairs},
          {"pure_rotation_share", support.pure_rotation_share},
          {"max_pure_rotation_share", support.thresholds.max_pure_rotation_share},
          {"median_parallax_deg", support.median_parallax_deg},
          {"num_images", support.positions.num_images},
          {"num_rotations_registered", support.positions.num_rotations_registered},
          {"num_positions_estimated", support.positions.num_positions_estimated},
          {"num_positions_filled", support.positions.num_positions_filled},
          {"filled_share", support.filled_share},
          {"max_filled_share", support.thresholds.max_filled_share}};
}

}  // namespace raytime

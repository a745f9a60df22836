#include "bootstrap/wrong_pairs.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>

#include "core/geometry.h"

namespace raytime {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Cycle statistics of every usable edge over the triangles of the usable graph.
void CountCycles(int num_nodes, const std::vector<ViewGraphEdge>& edges, double tolerance_deg,
                 std::vector<PairScore>* scores) {
  // cam_b_from_cam_a for both orientations of every usable edge.
  std::map<std::pair<int, int>, std::pair<int, Eigen::Matrix3d>> relative;
  std::vector<std::vector<int>> neighbours(num_nodes);
  for (size_t k = 0; k < edges.size(); ++k) {
    const ViewGraphEdge& e = edges[k];
    if (!e.UsableForRotation()) continue;
    relative[{e.image1, e.image2}] = {static_cast<int>(k), e.rotation};
    relative[{e.image2, e.image1}] = {static_cast<int>(k), e.rotation.transpose()};
    neighbours[e.image1].push_back(e.image2);
    neighbours[e.image2].push_back(e.image1);
  }
  const double tolerance = RadiansFromDegrees(tolerance_deg);
  for (int a = 0; a < num_nodes; ++a) {
    for (int b : neighbours[a]) {
      if (b <= a) continue;
      for (int c : neighbours[b]) {
        if (c <= b) continue;
        const auto ac = relative.find({a, c});
        if (ac == relative.end()) continue;
        const auto& ab = relative.at({a, b});
        const auto& bc = relative.at({b, c});
        // R_ca^T R_cb R_ba is the identity on a consistent triangle.
        const double error =
            RotationAngle(Eigen::Matrix3d(ac->second.second.transpose() * bc.second * ab.second));
        const bool consistent = error < tolerance;
        for (int k : {ab.first, bc.first, ac->second.first}) {
          ++(*scores)[k].cycle_triplets;
          if (consistent) ++(*scores)[k].cycle_consistent;
        }
      }
    }
  }
}

}  // namespace

std::vector<RelativeRotation> RotationEdges(const std::vector<ViewGraphEdge>& edges,
                                            const std::vector<int>& edge_indices) {
  std::vector<RelativeRotation> out;
  for (int k : edge_indices) {
    const ViewGraphEdge& e = edges[k];
    RelativeRotation r;
    r.i = e.image1;
    r.j = e.image2;
    r.cam_j_from_cam_i = e.rotation;
    r.weight = std::max(1, e.num_inliers);
    out.push_back(r);
  }
  return out;
}

std::vector<RelativeDirection> DirectionEdges(const std::vector<ViewGraphEdge>& edges,
                                              const std::vector<int>& edge_indices,
                                              const std::vector<Eigen::Matrix3d>& rotations) {
  std::vector<RelativeDirection> out;
  for (int k : edge_indices) {
    const ViewGraphEdge& e = edges[k];
    if (!e.UsableForTranslation()) continue;
    // `translation` is camera 1's centre seen from camera 2: O_1 - O_2 = s R_2 t.
    RelativeDirection d;
    d.i = e.image1;
    d.j = e.image2;
    d.direction = (rotations[e.image2] * e.translation).normalized();
    out.push_back(d);
  }
  return out;
}

PairClassification ClassifyPairs(int num_nodes, const std::vector<ViewGraphEdge>& edges,
                                 const WrongPairOptions& options,
                                 const RotationAveragingOptions& rotation_options,
                                 const TranslationAveragingOptions& translation_options,
                                 double direction_gate_deg) {
  ValidateOptions(options, "wrong pairs");
  if (!(direction_gate_deg > 0)) throw std::invalid_argument("direction_gate_deg must be > 0");
  PairClassification result;
  result.scores.resize(edges.size());
  std::vector<int> kept;
  for (size_t k = 0; k < edges.size(); ++k) {
    if (edges[k].image1 < 0 || edges[k].image2 < 0 || edges[k].image1 >= num_nodes ||
        edges[k].image2 >= num_nodes || edges[k].image1 == edges[k].image2) {
      throw std::invalid_argument("ClassifyPairs: edge " + std::to_string(k) +
                                  " has bad image indices");
    }
    PairScore& s = result.scores[k];
    s.rotation_residual_deg = s.direction_residual_deg = kNaN;
    if (edges[k].UsableForRotation()) {
      s.verdict = PairVerdict::kKept;
      kept.push_back(static_cast<int>(k));
    }
  }
  CountCycles(num_nodes, edges, options.cycle_tolerance_deg, &result.scores);

  // Rotations on the kept pairs, then centres from the kept pairs that pass the paper's gate:
  // only pairs whose rotation agrees within direction_gate_deg contribute a translation
  // direction (§4.8: it "removes symmetric-structure outliers").
  auto solve = [&](const std::vector<int>& pairs) {
    result.rotations = AverageRotations(num_nodes, RotationEdges(edges, pairs), rotation_options);
    std::vector<int> gated;
    for (size_t n = 0; n < pairs.size(); ++n) {
      const double residual = result.rotations.edge_residual_deg[n];
      if (std::isfinite(residual) && residual <= direction_gate_deg) gated.push_back(pairs[n]);
    }
    result.translations = AverageTranslations(
        num_nodes, DirectionEdges(edges, gated, result.rotations.world_from_cam),
        translation_options);
  };

  bool settled = false;
  for (int round = 0; round < options.wrong_pair_rounds && !settled; ++round) {
    ++result.rounds;
    solve(kept);
    const std::vector<Eigen::Matrix3d>& r = result.rotations.world_from_cam;
    const auto& centres = result.translations.centres;
    const auto& placed = result.translations.registered;

    // Re-score every usable pair, kept or not, against this round's solution; pairs of images
    // the solution does not register keep their previous verdict.
    std::vector<int> next;
    for (size_t k = 0; k < edges.size(); ++k) {
      const ViewGraphEdge& e = edges[k];
      PairScore& s = result.scores[k];
      if (!e.UsableForRotation()) continue;
      if (!result.rotations.registered[e.image1] || !result.rotations.registered[e.image2]) {
        if (s.verdict == PairVerdict::kKept) next.push_back(static_cast<int>(k));
        continue;
      }
      s.rotation_residual_deg = DegreesFromRadians(RotationAngle(
          Eigen::Matrix3d(e.rotation.transpose() * r[e.image2].transpose() * r[e.image1])));
      s.direction_residual_deg = kNaN;
      if (e.UsableForTranslation() && placed[e.image1] && placed[e.image2]) {
        const Eigen::Vector3d measured = r[e.image2] * e.translation;
        const Eigen::Vector3d solved = centres[e.image1] - centres[e.image2];
        s.direction_residual_deg =
            DegreesFromRadians(std::atan2(measured.cross(solved).norm(), measured.dot(solved)));
      }
      s.score = s.rotation_residual_deg / options.wrong_rotation_deg;
      if (std::isfinite(s.direction_residual_deg)) {
        s.score = std::max(s.score, s.direction_residual_deg / options.wrong_direction_deg);
      }
      s.verdict = s.score > 1.0 ? PairVerdict::kWrong : PairVerdict::kKept;
      if (s.verdict == PairVerdict::kKept) next.push_back(static_cast<int>(k));
    }
    settled = next == kept;
    kept = std::move(next);
  }
  // The reported solution is the one on the final kept set.
  if (!settled) solve(kept);
  result.kept = kept;
  for (const auto& s : result.scores) {
    if (s.verdict == PairVerdict::kWrong) ++result.num_wrong;
    if (s.verdict == PairVerdict::kUnusable) ++result.num_unusable;
  }
  return result;
}

}  // namespace raytime

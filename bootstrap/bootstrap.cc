#include "bootstrap/bootstrap.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "bootstrap/view_graph_builder.h"
#include "core/statistics.h"
#include "core/timing.h"

namespace raytime {
namespace {

// Registered images the translation component did not place get the look-at rule around the
// point nearest the optical axes of the placed cameras, at their median distance from it, so the
// seed keeps one frame and one scale and no camera lands on another's centre by construction.
int FillMissingCentres(const std::vector<Eigen::Matrix3d>& rotations,
                       const std::vector<bool>& registered, const std::vector<bool>& placed,
                       std::vector<Eigen::Vector3d>* centres) {
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero(), centroid = Eigen::Vector3d::Zero(),
                  mean_axis = Eigen::Vector3d::Zero();
  int count = 0;
  for (size_t i = 0; i < rotations.size(); ++i) {
    if (!placed[i]) continue;
    const Eigen::Vector3d axis = rotations[i].col(2);
    const Eigen::Matrix3d p = Eigen::Matrix3d::Identity() - axis * axis.transpose();
    a += p;
    b += p * (*centres)[i];
    centroid += (*centres)[i];
    mean_axis += axis;
    ++count;
  }
  centroid /= count;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(a);
  std::vector<double> distances;
  for (size_t i = 0; i < rotations.size(); ++i) {
    if (placed[i]) distances.push_back(((*centres)[i] - centroid).norm());
  }
  const double spread = std::max(FiniteUpperMedian(distances), 1e-6);
  // Nearly parallel axes have no well-defined meeting point: look at a point in front of the
  // centroid instead.
  const Eigen::Vector3d target = eigen.eigenvalues()(0) > 1e-3 * eigen.eigenvalues()(2)
                                     ? Eigen::Vector3d(a.ldlt().solve(b))
                                     : Eigen::Vector3d(centroid + spread * mean_axis.normalized());
  distances.clear();
  for (size_t i = 0; i < rotations.size(); ++i) {
    if (placed[i]) distances.push_back(((*centres)[i] - target).norm());
  }
  const double radius = std::max(FiniteUpperMedian(distances), 1e-6);
  int filled = 0;
  for (size_t i = 0; i < rotations.size(); ++i) {
    if (registered[i] && !placed[i]) {
      (*centres)[i] = target - radius * rotations[i].col(2);
      ++filled;
    }
  }
  return filled;
}

}  // namespace

void SolveGlobalPoses(int num_images, const BootstrapOptions& options, BootstrapResult* result) {
  ValidateOptions(options, "bootstrap");
  const auto start = std::chrono::steady_clock::now();
  const std::vector<ViewGraphEdge>& edges = result->edges;

  // Fragility is measured on every usable pair, before any pair is rejected: it is the amount
  // of disagreement in the raw match graph (paper §4.8).
  std::vector<int> usable;
  for (size_t k = 0; k < edges.size(); ++k) {
    if (edges[k].UsableForRotation()) usable.push_back(static_cast<int>(k));
  }
  const RotationAveragingResult all =
      AverageRotations(num_images, RotationEdges(edges, usable), options.rotation_averaging);
  result->fragility_residual_deg.assign(edges.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t n = 0; n < usable.size(); ++n) {
    result->fragility_residual_deg[usable[n]] = all.edge_residual_deg[n];
  }
  result->fragility.mean_residual_deg = all.mean_residual_deg;
  result->fragility.median_residual_deg = all.median_residual_deg;
  result->fragility.num_pairs = all.num_edges_used;
  result->fragility.threshold_deg = options.fragility_threshold_deg;
  result->fragility.fragile = all.mean_residual_deg > options.fragility_threshold_deg;

  result->pairs = ClassifyPairs(num_images, edges, options.wrong_pairs, options.rotation_averaging,
                                options.translation_averaging, options.direction_gate_deg);
  if (options.filter_pairs) {
    result->rotations = result->pairs.rotations;
    result->translations = result->pairs.translations;
  } else {
    result->rotations = all;
    std::vector<int> gated;
    for (size_t n = 0; n < usable.size(); ++n) {
      const double residual = all.edge_residual_deg[n];
      if (std::isfinite(residual) && residual <= options.direction_gate_deg) {
        gated.push_back(usable[n]);
      }
    }
    result->translations =
        AverageTranslations(num_images, DirectionEdges(edges, gated, all.world_from_cam),
                            options.translation_averaging);
  }

  result->world_from_cam = result->rotations.world_from_cam;
  result->rotation_registered = result->rotations.registered;
  result->num_rotations_registered = result->rotations.num_registered;
  result->centres.assign(num_images, Eigen::Vector3d::Zero());
  result->position_estimated.assign(num_images, false);
  result->num_positions_estimated = 0;
  result->num_positions_filled = 0;
  const bool lud = options.positions == "lud" && result->translations.num_registered >= 2;
  if (lud) {
    std::vector<bool>& placed = result->position_estimated;
    for (int i = 0; i < num_images; ++i) {
      placed[i] = result->rotation_registered[i] && result->translations.registered[i];
      if (placed[i]) {
        result->centres[i] = result->translations.centres[i];
        ++result->num_positions_estimated;
      }
    }
    result->num_positions_filled = FillMissingCentres(
        result->world_from_cam, result->rotation_registered, placed, &result->centres);
  } else {
    // The look-at seed; also the fallback when no translation direction survived (a graph of
    // pure rotations), since a seed with every camera at one point is degenerate (paper §4.8).
    std::vector<Eigen::Matrix3d> rotations;
    std::vector<int> index;
    for (int i = 0; i < num_images; ++i) {
      if (result->rotation_registered[i]) {
        rotations.push_back(result->world_from_cam[i]);
        index.push_back(i);
      }
    }
    result->look_at = LookAtSeed(rotations, options.look_at);
    for (size_t k = 0; k < index.size(); ++k)
      result->centres[index[k]] = result->look_at.centres[k];
    if (options.positions == "lud") result->num_positions_filled = static_cast<int>(index.size());
  }
  result->support =
      AssessGraphSupport(edges,
                         {num_images, result->num_rotations_registered,
                          result->num_positions_estimated, result->num_positions_filled},
                         options.graph_support);
  result->global_seconds = SecondsSince(start);
}

BootstrapResult RunBootstrap(const ImageSet& images, const std::vector<ImageFeatures>& features,
                             const std::vector<PairMatches>& matches,
                             const BootstrapOptions& options) {
  ValidateOptions(options, "bootstrap");
  const auto start = std::chrono::steady_clock::now();
  ViewGraphBuildResult graph = BuildViewGraph(images, features, matches, options.relative_pose,
                                              options.focal_search, options.focal);
  BootstrapResult result;
  result.edges = std::move(graph.edges);
  result.cameras = std::move(graph.cameras);
  result.focal_searches = std::move(graph.focal_searches);
  result.num_pairs_input = graph.num_pairs_input;
  result.relative_pose_seconds = SecondsSince(start);
  SolveGlobalPoses(static_cast<int>(images.images.size()), options, &result);
  return result;
}

const char* FragilityVerdict(const BootstrapResult& result) {
  if (result.fragility.fragile) return result.support.weak ? "fragile and weak" : "fragile";
  return result.support.weak ? "weak" : "not fragile";
}

BootstrapSummary SummarizeBootstrap(int num_images, const BootstrapOptions& options,
                                    const BootstrapResult& result) {
  BootstrapSummary s;
  s.num_images = num_images;
  s.num_pairs = static_cast<int>(result.edges.size());
  s.num_usable_pairs = result.support.num_usable_pairs;
  s.num_pure_rotation_pairs = result.support.num_pure_rotation_pairs;
  s.num_rotations_registered = result.num_rotations_registered;
  s.num_positions_estimated = result.num_positions_estimated;
  s.num_positions_filled = result.num_positions_filled;
  s.positions = options.positions;
  const FragilityReport& f = result.fragility;
  s.fragility = {f.mean_residual_deg, f.median_residual_deg, f.num_pairs,       f.threshold_deg,
                 f.fragile,           FragilityVerdict(result), result.support.reasons};
  s.graph_support = GraphSupportJson(result.support);
  s.pairs = {s.num_usable_pairs - result.pairs.num_wrong, result.pairs.num_wrong,
             result.pairs.num_unusable, result.pairs.rounds};
  const RotationAveragingResult& ra = result.rotations;
  s.rotation_averaging = {ra.num_edges_used,  ra.l1_iterations,     ra.irls_iterations,
                          ra.converged,       ra.mean_residual_deg, ra.median_residual_deg};
  const TranslationAveragingResult& ta = result.translations;
  s.translation_averaging = {ta.num_edges_used, ta.num_registered,    ta.iterations,
                             ta.converged,      ta.mean_residual_deg, ta.median_residual_deg};
  for (size_t c = 0; c < result.focal_searches.size(); ++c) {
    const FocalSearchResult& search = result.focal_searches[c];
    s.focal_search.push_back({static_cast<int>(c), search.focal_px, search.num_pairs,
                              search.candidates_px, search.inliers});
  }
  s.seconds = {result.relative_pose_seconds, result.global_seconds};
  s.guardrails = {f.fragile, f.mean_residual_deg, result.support.weak};
  return s;
}

Warnings BootstrapWarnings(const ImageSet& images, const BootstrapResult& result) {
  if (!result.support.weak) return {};
  Warning warning;
  warning.code = "weak_bootstrap";
  warning.message = "The view graph cannot support the bootstrap's estimate: " +
                    DescribeWeakness(result.support) + ".";
  const bool filled = result.num_positions_filled > 0;
  for (size_t i = 0; i < images.images.size() && i < result.rotation_registered.size(); ++i) {
    if (!result.rotation_registered[i] || (filled && !result.position_estimated[i])) {
      warning.images.push_back(images.images[i].name);
    }
  }
  warning.details = GraphSupportJson(result.support);
  return {warning};
}

PoseSet BootstrapPoses(const ImageSet& images, const BootstrapResult& result) {
  PoseSet poses;
  for (size_t i = 0; i < images.images.size() && i < result.rotation_registered.size(); ++i) {
    if (!result.rotation_registered[i]) continue;
    poses.world_from_cam[images.images[i].name] =
        Rigid3(Eigen::Quaterniond(result.world_from_cam[i]).normalized(), result.centres[i]);
  }
  return poses;
}

}  // namespace raytime

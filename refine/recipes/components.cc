#include "refine/recipes/components.h"

#include <limits>
#include <utility>

#include "core/graph.h"

namespace raytime {

MatchComponents SplitMatchComponents(const RefineInput& input) {
  const int n = static_cast<int>(input.prior_world_from_cam.size());
  std::vector<std::pair<int, int>> edges;
  std::vector<bool> matched(n, false);
  for (const PairMatchIndices& pair : input.pairs) {
    if (pair.matches.rows() == 0 || pair.image1 == pair.image2) continue;
    edges.emplace_back(pair.image1, pair.image2);
    matched[pair.image1] = matched[pair.image2] = true;
  }
  // Labels by decreasing size (core/graph.h); the unmatched images are singletons among them.
  const std::vector<int> labels = ConnectedComponents(n, edges);
  MatchComponents out;
  std::vector<std::vector<int>> by_label(n);
  for (int i = 0; i < n; ++i) {
    if (matched[i]) {
      by_label[labels[i]].push_back(i);
    } else {
      out.unmatched.push_back(i);
    }
  }
  for (std::vector<int>& component : by_label) {
    if (!component.empty()) out.components.push_back(std::move(component));
  }
  return out;
}

RefineInput ComponentInput(const RefineInput& input, const std::vector<int>& images) {
  RefineInput out;
  out.cameras = input.cameras;
  out.prior_rotations_from_matches = input.prior_rotations_from_matches;
  out.stated_prior = input.stated_prior;
  std::vector<int> local(input.prior_world_from_cam.size(), -1);
  for (size_t k = 0; k < images.size(); ++k) {
    const int i = images[k];
    local[i] = static_cast<int>(k);
    out.camera_index.push_back(input.camera_index.at(i));
    out.prior_world_from_cam.push_back(input.prior_world_from_cam.at(i));
    out.keypoints.push_back(input.keypoints.at(i));
    if (!input.names.empty()) out.names.push_back(input.names.at(i));
  }
  for (const PairMatchIndices& pair : input.pairs) {
    const int a = local.at(pair.image1), b = local.at(pair.image2);
    if (a < 0 || b < 0) continue;
    out.pairs.push_back({a, b, pair.matches});
  }
  for (const auto& [pass, poses] : input.warm_start.world_from_cam) {
    std::vector<std::optional<Rigid3>>& start = out.warm_start.world_from_cam[pass];
    start.resize(images.size());
    for (size_t k = 0; k < images.size(); ++k) {
      if (static_cast<size_t>(images[k]) < poses.size()) start[k] = poses[images[k]];
    }
  }
  for (const auto& [key, ray_time] : input.warm_start.ray_times) {
    const int image = static_cast<int>(key >> 32);
    if (image < 0 || static_cast<size_t>(image) >= local.size() || local[image] < 0) continue;
    out.warm_start.ray_times[WarmRayTimeKey(local[image], static_cast<int>(key & 0xffffffffu))] =
        ray_time;
  }
  return out;
}

void MergeComponentOutput(const std::vector<int>& images, const RefineOutput& part, bool cameras,
                          bool solution_returned, RefineOutput* whole) {
  const size_t n = whole->world_from_cam.size();
  for (size_t k = 0; k < images.size(); ++k) {
    whole->world_from_cam.at(images[k]) = part.world_from_cam[k];
    whole->solved_world_from_cam.at(images[k]) = part.solved_world_from_cam[k];
    whole->diagnostics.image_residual_median_px.at(images[k]) =
        k < part.diagnostics.image_residual_median_px.size()
            ? part.diagnostics.image_residual_median_px[k]
            : std::numeric_limits<double>::quiet_NaN();
  }
  if (cameras) {
    whole->cameras = part.cameras;
    whole->solved_cameras = part.solved_cameras;
  }
  for (PairResidual pair : part.diagnostics.pairs) {
    pair.image1 = images.at(pair.image1);
    pair.image2 = images.at(pair.image2);
    whole->diagnostics.pairs.push_back(pair);
  }
  if (!solution_returned) return;
  // Ray times: the component's observations after the ones already merged, its images renamed.
  SolvedObservations& rays = whole->solved_observations;
  const SolvedObservations& add = part.solved_observations;
  const Eigen::Index start = rays.observations.rows(), count = add.observations.rows();
  rays.observations.conservativeResize(start + count, 2);
  rays.ray_times.conservativeResize(start + count);
  for (Eigen::Index o = 0; o < count; ++o) {
    rays.observations.row(start + o) << images.at(add.observations(o, 0)), add.observations(o, 1);
    rays.ray_times(start + o) = add.ray_times(o);
  }
  const Eigen::Index match_start = rays.matches.rows();
  rays.matches.conservativeResize(match_start + add.matches.rows(), 2);
  for (Eigen::Index m = 0; m < add.matches.rows(); ++m) {
    rays.matches.row(match_start + m) << static_cast<int>(start) + add.matches(m, 0),
        static_cast<int>(start) + add.matches(m, 1);
  }
  for (const auto& [pass, poses] : part.pass_world_from_cam) {
    std::vector<std::optional<Rigid3>>& out = whole->pass_world_from_cam[pass];
    out.resize(n);
    for (size_t k = 0; k < images.size() && k < poses.size(); ++k) out[images[k]] = poses[k];
  }
}

namespace {

void ToInputIndices(const std::vector<int>& images, std::vector<PairResidual>* pairs) {
  for (PairResidual& pair : *pairs) {
    pair.image1 = images.at(pair.image1);
    pair.image2 = images.at(pair.image2);
  }
}

void ToInputIndices(const std::vector<int>& images, std::vector<int>* indices) {
  for (int& index : *indices) index = images.at(index);
}

// values[k] at images[k], `fill` elsewhere, `num_images` entries.
template <typename T>
void Scatter(const std::vector<int>& images, int num_images, const T& fill,
             std::vector<T>* values) {
  std::vector<T> out(num_images, fill);
  for (size_t k = 0; k < values->size() && k < images.size(); ++k) out[images[k]] = (*values)[k];
  *values = std::move(out);
}

}  // namespace

void ToInputIndices(const std::vector<int>& images, int num_images, RefineSummary* summary) {
  InconsistentPairsVerdict& pairs = summary->guardrails.inconsistent_pairs;
  ToInputIndices(images, &pairs.pairs);
  ToInputIndices(images, &pairs.images_mostly_inconsistent);
  LoosePartsVerdict& loose = summary->guardrails.loose_parts;
  for (LooseCut& cut : loose.cuts) ToInputIndices(images, &cut.images);
  ToInputIndices(images, &loose.images);
  ToInputIndices(images, &summary->pair_removal.removed);
  ToInputIndices(images, &summary->pair_removal.kept);
  Scatter(images, num_images, PoseUncertainty(), &summary->uncertainty.cameras);
  FrameDoubtVerdict& doubts = summary->frame_doubts;
  ToInputIndices(images, &doubts.images);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Scatter(images, num_images, nan, &doubts.centre_change);
  Scatter(images, num_images, nan, &doubts.residual_ratio);
  for (FrameIntrinsicsTest& test : summary->frame_intrinsics) test.image = images.at(test.image);
}

}  // namespace raytime

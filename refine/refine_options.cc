#include "refine/refine_options.h"

#include <thread>

#include "core/error.h"
#include "core/options.h"

namespace raytime {
namespace {

void Require(bool condition, const std::string& field, const std::string& expected) {
  if (!condition) throw InputError("refine option '" + field + "' must be " + expected);
}

}  // namespace

void RefineOptions::Validate() const {
  if (parameterization != "per_observation" && parameterization != "anchored") {
    throw InputError(UnknownKeyMessage("refine.parameterization", parameterization,
                                       {"per_observation", "anchored"}, "value"));
  }
  if (ray_time_init != "auto" && ray_time_init != "constant") {
    throw InputError(
        UnknownKeyMessage("refine.ray_time_init", ray_time_init, {"auto", "constant"}, "value"));
  }
  Require(loss_scale_px2 > 0, "loss_scale_px2", "positive");
  for (double scale : gnc_scales) Require(scale > 0, "gnc_scales", "a list of positive scales");
  Require(position_weight >= 0, "position_weight", "non-negative");
  Require(orientation_weight >= 0, "orientation_weight", "non-negative");
  Require(gauge_orientation_weight >= 0, "gauge_orientation_weight", "non-negative");
  Require(ray_time_constant_m > 0, "ray_time_constant_m", "positive");
  Require(max_matches_per_pair >= 0, "max_matches_per_pair", "non-negative (0 keeps all)");
  Require(num_threads >= 0, "num_threads", "non-negative (0 = hardware concurrency)");
  Require(max_iterations > 0, "max_iterations", "positive");
  Require(function_tolerance > 0, "function_tolerance", "positive");
  Require(trust_region_rotation_deg > 0, "trust_region_rotation_deg", "positive");
  Require(trust_region_translation_m > 0, "trust_region_translation_m", "positive");
  Require(length_unit_m > 0, "length_unit_m", "positive");
  Require(wander_expected_m > 0, "wander_expected_m", "positive");
  Require(wander_factor > 0, "wander_factor", "positive");
  Require(inconsistent_pair_px > 0, "inconsistent_pair_px", "positive");
  Require(max_inconsistent_pair_fraction >= 0 && max_inconsistent_pair_fraction < 1,
          "max_inconsistent_pair_fraction", "in [0, 1)");
  Require(stage1_orientation_weight >= 0, "stage1_orientation_weight", "non-negative");
  Require(stage1_max_matches_per_pair >= 0, "stage1_max_matches_per_pair",
          "non-negative (0 keeps all)");
}

std::vector<double> RefineOptions::StageScales() const {
  std::vector<double> scales = gnc_scales;
  if (scales.empty() || scales.back() != loss_scale_px2) scales.push_back(loss_scale_px2);
  return scales;
}

int RefineOptions::Threads() const {
  if (num_threads > 0) return num_threads;
  return std::max(1u, std::thread::hardware_concurrency());
}

}  // namespace raytime

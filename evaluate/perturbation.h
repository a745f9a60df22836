// Perturbation of ground-truth poses into a synthetic prior (SPEC §6; paper §4.8 "Basin of
// convergence"). Deterministic for a given seed.
#pragma once

#include <string>

#include "core/options.h"
#include "core/types.h"

namespace raytime {

struct PerturbationOptions {
  // "iid": every frame rotated by exactly level_deg about a uniform random axis and its centre
  // moved by level_deg * translation_per_deg in a uniform random direction.
  // "random_walk": a per-frame random walk whose mean per-frame magnitude equals the i.i.d. one.
  // "kidnap": frames split into three contiguous segments (name order), each moved rigidly by
  // one i.i.d. draw at the level.
  std::string mode = "iid";
  double level_deg = 0.0;  // degrees
  // Centre displacement per degree of rotation: metres when translation_unit is "metres", else a
  // fraction of the median camera-to-scene distance (data README: 1.25 % per degree).
  double translation_per_deg = 0.0125;
  std::string translation_unit = "scene_fraction";  // "scene_fraction" or "metres"
  // Median camera-to-scene distance, metres; 0 estimates it from the ground truth as the median
  // distance from each centre to the point nearest all optical axes.
  double scene_distance_m = 0.0;
  int seed = 0;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("mode", mode,
      "Perturbation: every frame by the level, a random walk of equal mean, or three rigid "
      "segments (§4.8)",
      OneOf({"iid", "random_walk", "kidnap"}));
    v("level_deg", level_deg, "Rotation per frame, degrees (§4.8 ladder: 1, 2, 4, ... 64)",
      NonNegative(), AtMost(180));
    v("translation_per_deg", translation_per_deg,
      "Centre displacement per degree, in translation_unit (1.25 % of the scene per degree; at "
      "most 1 scene distance or 1 km per degree)",
      NonNegative(), AtMost(1000));
    v("translation_unit", translation_unit,
      "Unit of translation_per_deg: fraction of the camera-to-scene distance, or metres",
      OneOf({"scene_fraction", "metres"}));
    v("scene_distance_m", scene_distance_m,
      "Median camera-to-scene distance, metres (at most 1000 km); 0 estimates it from the "
      "ground truth",
      NonNegative(), AtMost(1e6));
    v("seed", seed, "Seed of the perturbation draws");
  }
  // A perturbation beyond a scene distance per degree moves the cameras out of the scene: no
  // prior, and at 1e308 not even a number.
  void CheckRelations(const Requirement& require) const {
    require(translation_unit != "scene_fraction" || translation_per_deg <= 1.0,
            "translation_per_deg " + std::to_string(translation_per_deg) +
                " scene distances per degree moves every camera out of the scene (at most 1)");
  }
};

struct PerturbationSummary {
  double translation_m = 0.0;     // centre displacement magnitude used at this level, metres
  double scene_distance_m = 0.0;  // given or estimated
};

// Validates the options (InputError naming the bad key) and returns the perturbed poses.
PoseSet PerturbPoses(const PoseSet& ground_truth, const PerturbationOptions& options,
                     PerturbationSummary* summary = nullptr);

// Median distance from each camera centre to the least-squares point nearest all optical axes.
double EstimateSceneDistance(const PoseSet& poses);

}  // namespace raytime

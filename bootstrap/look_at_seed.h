// Look-at position seed (SPEC §4 (b); paper §4.8 "Refinement without an external prior": "each
// camera at unit distance behind its optical axis, assuming only a commonly faced object").
#pragma once

#include <Eigen/Core>
#include <vector>
#include "core/options.h"

namespace raytime {

struct LookAtSeedOptions {
  // Distance of every camera from the common look-at point (the origin), scene units.
  double look_at_distance = 1.0;
  // Smallest RMS distance of the centres from their centroid, as a fraction of
  // look_at_distance. Below it (cameras sharing one optical axis direction, as in a pure
  // panorama or a forward-facing sequence) the plain construction nearly puts every camera at
  // one point, where all ray-time gradients vanish (paper §4.8), so the centres are spread on a
  // ring across the mean optical axis instead.
  double look_at_min_spread = 0.1;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("look_at_distance", look_at_distance,
      "Look-at seed: distance of every camera from the look-at point, scene units", Positive(),
      AtMost(1e9));
    v("look_at_min_spread", look_at_min_spread,
      "Look-at seed: smallest RMS centre spread, fraction of look_at_distance (else a ring)",
      Positive(), AtMost(1000));
  }
};

struct LookAtSeedResult {
  std::vector<Eigen::Vector3d> centres;  // one per rotation
  double spread = 0.0;           // RMS distance of the centres from their centroid, scene units
  bool spread_fallback = false;  // the ring spread was applied
};

// O_i = -look_at_distance * R_i e_z for camera-to-world rotations R_i, so every optical axis
// passes through the origin. The centres never collapse: with two or more cameras their spread
// is at least look_at_min_spread * look_at_distance.
LookAtSeedResult LookAtSeed(const std::vector<Eigen::Matrix3d>& world_from_cam,
                            const LookAtSeedOptions& options);

}  // namespace raytime

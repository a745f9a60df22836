// Gauge polish after a solve: the match term of paper eq. (energy) is invariant under a global
// similarity of the observed cameras (X = O + t·D maps to sR·X + T with t scaled by s), so along
// those 7 directions only the prior terms curve the energy, some 1e-7 of the match term's
// curvature. Levenberg–Marquardt's diagonal damping barely moves along them and stops on the
// function tolerance first: with λR = 0 an exact prior came back up to 0.5° off in the prior's
// own frame while the shape was exact (bench/refine_bench.cc, [5]). This step finishes those
// directions exactly: it fits the similarity minimizing the prior terms (a 7-parameter Ceres
// problem) and applies it to the observed cameras and the ray times. The match term is
// unchanged and Sim(3)-aligned errors are unchanged by construction. The fit weighs the
// orientation prior by its own λR (RefineOptions::gauge_orientation_weight), which may differ from
// the solve's: the prior costs reported are those of E (the solve's weights), so E decreases when
// the two agree and may rise slightly when the fit trusts the prior's rotations more than E does.
#pragma once

#include <nlohmann/json.hpp>
#include <vector>

#include "core/geometry.h"

namespace raytime {

struct GaugePolishSummary {
  // λp/N Σ|O - O^prior|² + λR/N Σ|Log(...)|² over the observed cameras, with the solve's λR.
  double prior_cost_before = 0.0;
  double prior_cost_after = 0.0;
  double rotation_deg = 0.0;  // the applied similarity
  double translation = 0.0;   // prior length units
  double scale = 1.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(GaugePolishSummary, prior_cost_before, prior_cost_after,
                                   rotation_deg, translation, scale)

// `movable[i]` marks the cameras some residual reaches (the others keep their poses); ray times
// are scaled with the similarity's scale. The similarity minimizes the prior terms with
// `gauge_orientation_weight` as λR; the summary's costs use `orientation_weight` (the solve's).
GaugePolishSummary PolishGauge(const std::vector<Rigid3>& prior, const std::vector<bool>& movable,
                               double position_weight, double orientation_weight,
                               double gauge_orientation_weight, std::vector<Rigid3>* world_from_cam,
                               std::vector<double>* ray_times);

}  // namespace raytime

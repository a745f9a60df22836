// The refine stage's work on a scene whose images are known by name (issue 48: refine owns its
// work; pipelines/refine_stage.cc only reads the work directory's HDF5 files, calls RefineScene
// and writes the result back):
//
//   1. the prior's convention against the verified pairs' own relative poses (a prior in another
//      convention is refused before any solve; prior_convention.h),
//   2. the refiner's input: the images with a prior pose and the verified pairs between them,
//   3. a warm start from an earlier solution of the same images (by name, issue 34),
//   4. RefinePoses (refine.h),
//   5. its output by image name: the refined pose set (without the frames no solve refined), the
//      frame verdicts, the uncertainty, the solve diagnostics, the ray times, the poses at the end
//      of each pass (a later run's warm start) and, self-calibrating, the refined cameras.
#pragma once

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/features.h"
#include "core/types.h"
#include "refine/checks/prior_convention.h"
#include "refine/refine_options.h"
#include "refine/refine_types.h"

namespace raytime {

// A solution of an earlier run, by image name: per pass, the poses at its end; per image and
// keypoint row, the pixel (to check the keypoint is still the same) and its ray time.
struct EarlierSolution {
  std::map<std::string, std::map<std::string, Rigid3>> pass_poses;
  std::map<std::string, std::map<uint32_t, std::pair<Eigen::Vector2d, double>>> rays;
  bool empty() const { return pass_poses.empty(); }
};

// The earlier solution from what RefineScene wrote: SceneResult::pass_poses and ray_times.
// InputError when the poses are not [qw, qx, qy, qz, x, y, z].
EarlierSolution EarlierSolutionOf(const nlohmann::json& pass_poses,
                                  const RayTimeObservations& rays);

struct SceneInput {
  const ImageSet* images = nullptr;
  const std::vector<ImageFeatures>* features = nullptr;  // one per image of `images`
  const std::vector<PairMatches>* matches = nullptr;     // verified pairs
  const PoseSet* prior = nullptr;
  // Where the prior, the features and the matches come from, for the messages ("pose set
  // 'prior' of WORKDIR/prior.h5", "WORKDIR/features.h5").
  std::string prior_source;
  std::string features_source;
  std::string matches_source;
  // The prior's rotations were made from the match graph (the bootstrap's): no convention check.
  bool prior_rotations_from_matches = false;
  StatedPriorAccuracy stated_prior;
  bool check_prior_convention = true;
  EarlierSolution earlier;  // empty: no warm start
};

struct SceneResult {
  RefineSummary summary;
  PriorConventionVerdict convention;
  size_t num_images_without_prior = 0;
  PoseSet refined;  // the frames a solve refined (their verdict says how far it holds them)
  nlohmann::json frame_verdicts;  // name -> FrameVerdict
  nlohmann::json uncertainty;     // name -> σ (frames refined, not returned as the prior)
  nlohmann::json diagnostics;     // {images, pairs, removed} by name (kSolveDiagnosticsJson)
  nlohmann::json pass_poses;      // pass -> name -> [qw, qx, qy, qz, x, y, z]
  RayTimeObservations ray_times;
  // Self-calibrating: the images with their refined cameras, and those cameras in words.
  std::optional<ImageSet> refined_images;
  nlohmann::json refined_intrinsics;
};

// Whether a frame whose verdict gives `reason` was refined by a solve: not when no solve took it
// (unmatched, not_solved), a guardrail returned the prior's pose (returned_prior) or the solve's
// pose is not finite (non_finite). Its pose in SceneResult::refined, if any, is then no refined
// pose.
bool RefinedBySolve(const std::string& reason);

// Steps 1-5 above. InputError when the prior is refused (its convention) or no verified pair joins
// two images with a prior pose, and as RefinePoses on inconsistent input.
SceneResult RefineScene(const SceneInput& input, const RefineOptions& options);

}  // namespace raytime

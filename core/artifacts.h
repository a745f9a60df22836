// The names of what a work directory holds: the artifacts the stages read and write and the JSON
// documents beside pose sets. Stages meet through them (pipelines/) and the run page reads them
// (report/), so they are core's vocabulary rather than either layer's.
#pragma once

#include <string>

namespace raytime {

// Artifact names: what a stage reads and writes. Each lives in the HDF5 file of the stage that
// wrote it last.
inline constexpr const char* kArtifactImages = "images";
inline std::string PoseArtifact(const std::string& pose_set) { return "poses/" + pose_set; }
// A nerfstudio dataset's transforms.json as read, {path, text}: a JSON document of the dataset
// stage's output, which the export writes back with the refined poses (nerfstudio_in_place).
inline constexpr const char* kArtifactNerfstudioTransforms = "nerfstudio_transforms";
// JSON document beside a refined pose set: per image name (every image with a prior pose), its
// verdict {verdict: held | held_by_prior | doubted, reason, detail}
// (refine/checks/frame_verdicts.h). Written by refine; the export leaves the doubted frames out
// (never a silent wrong result) and writes the verdicts beside the poses.
inline constexpr const char* kFrameVerdictsJson = "frame_verdicts";
// JSON document beside a prior pose set: the accuracy its maker states, {sigma_deg, sigma_m} per
// frame (prior stage options sigma_deg, sigma_m; absent when none is stated). Read by refine.
inline constexpr const char* kPriorAccuracyJson = "prior_accuracy";
// JSON document beside a refined pose set: per image name, σ of its rotation (degrees) and centre
// (prior length units) at the solution (refine/checks/pose_uncertainty.h). Written by refine.
inline constexpr const char* kPoseUncertaintyJson = "pose_uncertainty";
// JSON document beside a refined pose set: how each solve fits its matches at the solution
// (refine's SolveDiagnostics): "images" {name: {residual_median_px, num_pairs, num_matches}} and
// "pairs" [[name1, name2, num_matches, median_px], ...] (the pairs each solve used) and "removed"
// (the same for the pairs the wrong-pair removal took, with their measure when removed). Written by
// refine, read by the run page.
inline constexpr const char* kSolveDiagnosticsJson = "solve_diagnostics";
// JSON document beside a repaired prior pose set: what the prior stage's repair did (mode "none",
// "rotations" or "replace", and "pose_set"). Written by prior, read by refine.
inline constexpr const char* kPriorRepairJson = "prior_repair";

}  // namespace raytime

// Does another focal length or principal point explain a frame's matches far better than its own
// (issue 46; beyond the paper, which self-calibrates one shared camera, §3.1)? A frame given wrong
// intrinsics (an EXIF focal of the wrong lens, a crop that kept the full frame's principal point)
// is placed by the solve where its rays fit best, metres off with every pair still nearly
// explained: an 8-image scene with one focal 1.4x its true value put that frame 4 m off on a 5 m
// scene, and only the pairs it is in were flagged. Per frame, with every other frame held at the
// solution, its pose is fitted to the epipolar geometry of its matches with its intrinsics as
// given, and again with the focal length (one factor for fx and fy), the principal point or both
// free; a
// frame whose matches a fit freeing the focal length, the principal point or both explains
// kMinIntrinsicsImprovement times better, by a material change of intrinsics, is named with the
// factor and the shift. No structure is built: each match is the
// distance, in the frame's pixels, of its keypoint from the epipolar plane the other frame's ray
// spans with the two centres.
#pragma once

#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "refine/checks/frame_verdicts.h"
#include "refine/refine_types.h"

namespace raytime {

// Frames whose median over their pairs fits at least this multiple of the median frame's are
// fitted (a frame that fits like the others has nothing for other intrinsics to explain) ...
inline constexpr double kMinIntrinsicsGivenMultiple = 1.5;
// ... and the free fit must cut the median over the pairs explained (by either) by this factor ...
inline constexpr double kMinIntrinsicsImprovement = 1.5;
// ... from at least this many pixels (SIFT locates keypoints to about half a pixel: below, a
// frame's "worse" fit is noise) ...
inline constexpr double kMinIntrinsicsGivenPx = 0.25;
// ... with the focal length off by this fraction or the principal point by this fraction of the
// image width (less is within what a solve's noise can trade for pose).
inline constexpr double kMinFocalChange = 0.03;
inline constexpr double kMinPrincipalPointChange = 0.01;
// Frames with fewer sampled matches are not tested (a focal needs the geometry of several).
inline constexpr int kMinIntrinsicsMatches = 30;

// Every image with enough matches, tested at `world_from_cam` with its intrinsics
// `intrinsics[image]`, a pair explained when its median is within `explained_pair_px`; the named
// ones as findings (reason "intrinsics").
std::vector<FrameFinding> CheckFrameIntrinsics(const RefineInput& input,
                                               const std::vector<Rigid3>& world_from_cam,
                                               const std::vector<CameraIntrinsics>& intrinsics,
                                               double explained_pair_px, int num_threads,
                                               std::vector<FrameIntrinsicsTest>* tests);

}  // namespace raytime

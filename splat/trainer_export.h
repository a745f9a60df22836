// The trainer-ready export of pose sets for 3D Gaussian Splatting (SPEC §7, issue 11): per pose set
// a folder the gsplat, Inria and nerfstudio trainers read as it is,
//
//   <root>/<pose set>/images/<name>            undistorted (splat/undistortion.h), identical
//                                               for every pose set
//                    sparse/0/{cameras,images,points3D}.{bin,txt}   PINHOLE cameras
//                    transforms.json, sparse_pc.ply                 nerfstudio
//                    test.txt, train.txt                            the split
//
// and initial points taken from a refined solve's ray times instead of a triangulation: each
// observation's point on its ray (SPEC §3 "Ray point"), merged per track where the solve's matches
// chain, with the images' colours. Every pose set of one export has the same images, cameras,
// split, tracks and 2D points; only the poses (and the points' frame) differ.
//
// The numeric kernels (split, track merging) take plain Eigen arguments; ExportForTrainers does
// the files.
#pragma once

#include <Eigen/Core>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/features.h"
#include "core/options.h"
#include "core/types.h"
#include "core/warnings.h"
#include "splat/undistortion.h"

namespace raytime {

// --- The split ----------------------------------------------------------------------------------

// Both trainers' held-out split: images sorted by name, every `every`-th from the first (index %
// every == 0) is a test image (gsplat `test_every=8`, Inria `--eval` `llffhold=8`).
struct TrainTestSplit {
  std::vector<std::string> train;  // sorted
  std::vector<std::string> test;   // sorted
};
TrainTestSplit SplitEveryNth(std::vector<std::string> names, int every);

// --- Points from ray times ----------------------------------------------------------------------

// Observations of a solve, in one frame: rows are observations.
struct TrackObservations {
  Eigen::VectorXi image;  // index into the projections below
  // The observation's point on its ray (world); a row of NaN when it owns no ray time.
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> points;
  // Its pixel in its image's pinhole (undistorted) camera, OpenCV convention.
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> pixels;
  // Its image's colour at the keypoint, RGB in [0, 255].
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> colours;
  // Matches between observations (rows of the above): tracks are their connected components.
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
};

struct MergedTrack {
  Eigen::Vector3d xyz;            // the median of its observations' points, per coordinate
  Eigen::Vector3d rgb;            // the mean of its observations' colours
  double mean_error_px = 0.0;     // mean reprojection error over its observations
  std::vector<int> observations;  // rows of TrackObservations, ascending
};

struct TrackMergeSummary {
  int num_tracks = 0;  // connected components with at least two observations
  int num_kept = 0;
  int num_without_ray_time = 0;   // dropped: no observation owns a ray time
  int num_disagreeing = 0;        // dropped: beyond max_error_px in some observation
  int num_behind_camera = 0;      // dropped: behind some observing camera
  int num_observations_kept = 0;  // observations of kept tracks
  int num_duplicates_merged = 0;  // kept tracks at exactly another's point, merged into it
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(TrackMergeSummary, num_tracks, num_kept, num_without_ray_time,
                                   num_disagreeing, num_behind_camera, num_observations_kept,
                                   num_duplicates_merged)

// Tracks = connected components of the matches (union-find over observations). A track's point is
// the per-coordinate median of the points of its observations that own a ray time, its colour the
// mean of all its observations' colours. A track is kept only when its point lies in front of
// every camera observing it and reprojects within `max_error_px` of every one of its observations
// (with `projections[i]` = K_i [R_i | t_i], camera i's 3x4 pinhole projection): a chain that
// merged two different scene points (a wrong match) disagrees with itself and is dropped whole,
// since no single point explains it. Kept tracks at bitwise the same point (the copies of a SIFT
// keypoint with two orientations, matched alike) are merged into the first. Kept tracks are in
// order of their first observation.
std::vector<MergedTrack> MergeTracks(const TrackObservations& observations,
                                     const std::vector<Eigen::Matrix<double, 3, 4>>& projections,
                                     double max_error_px, TrackMergeSummary* summary);

// --- The export ---------------------------------------------------------------------------------

struct TrainerExportOptions {
  UndistortionOptions undistortion;
  // Every `test_every`-th image by name is held out (gsplat and Inria: 8, paper §4.5).
  int test_every = 8;
  // A track is dropped when its merged point reprojects farther than this from one of its
  // observations, pixels (COLMAP's own filter_max_reproj_error is 4 px).
  double max_track_error_px = 4.0;
  // JPEG quality of re-encoded (undistorted) images; colmap image_undistorter writes 100.
  int jpeg_quality = 100;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    undistortion.VisitFields(v);
    v("test_every", test_every,
      "3dgs: every N-th image by name is held out for testing (gsplat, Inria: 8; paper §4.5)",
      AtLeast(2), AtMost(1e6));
    v("max_track_error_px", max_track_error_px,
      "3dgs: drop a track whose merged point reprojects farther than this from one of its "
      "observations, pixels",
      Positive(), AtMost(1e6));
    v("jpeg_quality", jpeg_quality, "3dgs: JPEG quality of undistorted images (colmap: 100)",
      AtLeast(1), AtMost(100));
  }
  void CheckRelations(const Requirement& require) const { undistortion.CheckRelations(require); }
};

// The points' source: a refined solve's observations (RayTimeObservations, read with its pose
// set) at the poses `poses` they were solved for.
struct RayTimeSource {
  std::string pose_set;
  PoseSet poses;
  RayTimeObservations rays;
};

// What one call wrote.
struct TrainerExportSummary {
  std::vector<std::string> pose_sets;
  std::vector<std::string> directories;
  int num_images = 0;
  int num_images_undistorted = 0;  // resampled and re-encoded
  int num_images_copied = 0;       // without distortion: the file's bytes
  int num_train = 0;
  int num_test = 0;
  // Per camera used: the undistorted size over the distorted size (1 when copied).
  std::vector<double> undistortion_scale_x;
  std::vector<double> undistortion_scale_y;
  std::string points_from;  // the source's pose set, "" when no points were written
  int num_points = 0;
  TrackMergeSummary tracks;
  // Per pose set: how the points were brought into its frame ("solve", "sim3", "none") and the
  // median reprojection error of the points over their observations there, pixels.
  std::map<std::string, std::string> points_frame;
  std::map<std::string, double> reprojection_median_px;
  double seconds = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(TrainerExportSummary, pose_sets, directories, num_images,
                                   num_images_undistorted, num_images_copied, num_train, num_test,
                                   undistortion_scale_x, undistortion_scale_y, points_from,
                                   num_points, tracks, points_frame, reprojection_median_px,
                                   seconds)

// Writes <root>/<pose set>/ for each of `poses` (name -> poses), each folder atomically. `images`
// lists exactly the images to export (each with a pose in every set, which may hold more; the
// caller decides which),
// with their distorted cameras; the files are read from images.image_root. `source`, when given,
// supplies the points: in the source's own pose set as solved, in any other through the Sim(3)
// that maps the source's camera centres onto that set's (Umeyama, over the exported images);
// without a source, or where no such Sim(3) exists (fewer than three centres, collinear), the
// points3D are empty and a warning says so (`no_initial_points`). `frame_fields`, per pose set,
// per image name: fields added to its transforms.json frame (raytime's verdict and σ). Throws
// InputError on an unreadable image or an image whose size is not its camera's.
TrainerExportSummary ExportForTrainers(
    const ImageSet& images, const std::map<std::string, PoseSet>& poses,
    const std::optional<RayTimeSource>& source, const TrainerExportOptions& options,
    const std::string& root, Warnings* warnings,
    const std::map<std::string, nlohmann::json>& frame_fields = {});

// Whether `relative`, a path in a trainer-ready folder, is one trainers derive from the export on
// first use: Inria converts points3D.bin to sparse/0/points3D.ply; gsplat and nerfstudio write
// downscaled copies to images_<N>*/. Stale once the export is written again.
bool TrainerDerivedPath(const std::string& relative);

}  // namespace raytime

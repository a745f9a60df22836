// The classical control arm (SPEC §6; paper §4.1 "Classical control", §4.8 "Basin of
// convergence"): COLMAP 3.8 seeded with the pose prior, on the same matches as every other arm.
//
// "triangulate" mode follows COLMAP's reconstruct-from-known-poses recipe: the prior is written
// as a text model with an empty points3D.txt, then `point_triangulator` and `bundle_adjuster`
// alternate for `rounds` rounds, each round re-triangulating from the previous adjustment
// (point_triangulator keeps the points it is given and adds, merges and completes tracks under
// its gates; --clear_points stays at COLMAP's default 0). point_triangulator holds poses and
// cameras fixed; only bundle_adjuster moves them. "mapper" mode is COLMAP's prior-free
// incremental `mapper` on the same database (the prior-free anchor of §4.8); its poses live in an
// arbitrary similarity frame, and with refine_intrinsics the database must hold OPENCV cameras
// (WriteColmapDatabase's camera_model) for distortion to be refined.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/options.h"
#include "core/types.h"

namespace raytime {

struct ClassicalControlOptions {
  // "triangulate" (prior-seeded, §4.1) or "mapper" (prior-free, §4.8).
  std::string mode = "triangulate";
  // Triangulate-adjust alternations ("triangulate" mode): 2 in §4.1, 8 in the tuned control.
  int rounds = 2;
  // false: focal length, principal point and distortion fixed (§4.1). true: the room protocol of
  // §4.3, the OPENCV camera model with focal, principal-point and distortion refinement.
  bool refine_intrinsics = false;
  // Triangulation gates (COLMAP's Mapper.* options, COLMAP 3.8 defaults). The tuned control of
  // §4.8 loosens them to 8° / 16 px.
  // Mapper.tri_create_max_angle_error and tri_continue_max_angle_error, degrees.
  double max_angle_error_deg = 2.0;
  // Mapper.tri_merge_max_reproj_error, tri_complete_max_reproj_error and
  // filter_max_reproj_error, pixels.
  double max_reproj_error_px = 4.0;
  // Mapper.tri_min_angle and filter_min_tri_angle, degrees.
  double min_tri_angle_deg = 1.5;
  // The COLMAP 3.8 executable.
  std::string colmap = "colmap";

  // The tuned control of §4.8: eight rounds, gates loosened to 8° / 16 px.
  static ClassicalControlOptions Tuned();

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("mode", mode,
      "COLMAP point_triangulator + bundle_adjuster from the prior (§4.1), or the prior-free "
      "mapper (§4.8)",
      OneOf({"triangulate", "mapper"}));
    v("rounds", rounds, "Triangulate-adjust alternations (§4.1: 2; tuned control: 8)", Positive(),
      AtMost(100));
    v("refine_intrinsics", refine_intrinsics,
      "Refine focal, principal point and distortion (OPENCV model, room protocol §4.3)");
    v("max_angle_error_deg", max_angle_error_deg,
      "COLMAP triangulation angle-error gates, degrees (tuned control: 8)", Positive(),
      AtMost(180));
    v("max_reproj_error_px", max_reproj_error_px,
      "COLMAP merge/complete/filter reprojection gates, pixels (tuned control: 16)", Positive(),
      AtMost(1e4));
    v("min_tri_angle_deg", min_tri_angle_deg, "COLMAP minimum triangulation angle, degrees",
      NonNegative(), AtMost(90));
    v("colmap", colmap, "The COLMAP 3.8 executable", NonEmpty());
  }
};

struct ClassicalRoundSummary {
  double triangulate_s = 0.0;  // point_triangulator (or mapper) wall time
  double adjust_s = 0.0;       // bundle_adjuster wall time
  int num_points = 0;          // 3D points after the round
  // COLMAP's bundle adjustment report, "Final cost" (RMS reprojection error, px); NaN when the
  // log holds none.
  double colmap_final_cost_px = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ClassicalRoundSummary, triangulate_s, adjust_s, num_points,
                                   colmap_final_cost_px)

struct ClassicalControlSummary {
  std::string mode;
  int rounds = 0;
  std::vector<ClassicalRoundSummary> per_round;
  int num_images = 0;        // images in the ImageSet
  int num_registered = 0;    // images with a pose in the result
  int num_points = 0;        // 3D points of the result
  int num_observations = 0;  // track elements of the result
  // Mean reprojection error over all observations of the result, recomputed from the model with
  // its cameras (px); COLMAP's own last "Final cost" is colmap_final_cost_px.
  double mean_reprojection_error_px = 0.0;
  double colmap_final_cost_px = 0.0;
  double wall_time_s = 0.0;
  std::string model_dir;  // the final COLMAP model (binary)
  std::string log_path;   // every COLMAP command and its output

  nlohmann::json ToJson() const;  // the fields by name, NaN costs as null
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ClassicalControlSummary, mode, rounds, per_round, num_images,
                                   num_registered, num_points, num_observations,
                                   mean_reprojection_error_px, colmap_final_cost_px, wall_time_s,
                                   model_dir, log_path)

// Runs the control on `database_path` (a COLMAP database whose image ids are the 1-based
// positions in `images`, as WriteColmapDatabase writes it) with the images under
// images.image_root. `prior` seeds "triangulate" mode (images without a prior pose stay
// unregistered; a pose without an image is an InputError) and is ignored by "mapper". Everything
// goes below `workdir` (prior/, round_<k>/{triangulated,adjusted}/ or mapper/, colmap.log). Returns
// the refined world_from_cam poses of the images COLMAP kept. A failing COLMAP call is a
// runtime_error naming the command and the log file.
PoseSet RunClassicalControl(const std::string& database_path, const ImageSet& images,
                            const PoseSet& prior, const ClassicalControlOptions& options,
                            const std::string& workdir, ClassicalControlSummary* summary);

}  // namespace raytime

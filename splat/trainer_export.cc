#include "splat/trainer_export.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <stdexcept>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/graph.h"
#include "core/statistics.h"
#include "core/timing.h"
#include "core/written_files.h"
#include "formats/colmap_model.h"
#include "formats/nerfstudio.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Seconds between progress lines on long work.
constexpr double kProgressSeconds = 5.0;

// The pixel of `projection` a world point lands on, and its depth (z in the camera).
Eigen::Vector2d Project(const Eigen::Matrix<double, 3, 4>& projection, const Eigen::Vector3d& x,
                        double* depth) {
  const Eigen::Vector3d p = projection.leftCols<3>() * x + projection.col(3);
  *depth = p.z();
  return p.head<2>() / p.z();
}

// K [R | t] of a pinhole camera at `world_from_cam`.
Eigen::Matrix<double, 3, 4> ProjectionOf(const CameraIntrinsics& pinhole,
                                         const Rigid3& world_from_cam) {
  Eigen::Matrix3d K;
  K << pinhole.fx(), 0.0, pinhole.cx(), 0.0, pinhole.fy(), pinhole.cy(), 0.0, 0.0, 1.0;
  return K * world_from_cam.Inverse().Matrix3x4();
}

// Bilinear RGB of an 8-bit BGR image at an OpenCV pixel position (clamped to the image).
Eigen::Vector3d ColourAt(const cv::Mat& bgr, const Eigen::Vector2d& pixel) {
  const double x = std::clamp(pixel.x(), 0.0, bgr.cols - 1.0);
  const double y = std::clamp(pixel.y(), 0.0, bgr.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), bgr.cols - 1),
            y0 = std::min(static_cast<int>(y), bgr.rows - 1);
  const int x1 = std::min(x0 + 1, bgr.cols - 1), y1 = std::min(y0 + 1, bgr.rows - 1);
  const double dx = x - x0, dy = y - y0;
  Eigen::Vector3d rgb;
  for (int c = 0; c < 3; ++c) {
    const auto at = [&](int row, int col) { return double(bgr.at<cv::Vec3b>(row, col)[2 - c]); };
    rgb[c] = (1 - dy) * ((1 - dx) * at(y0, x0) + dx * at(y0, x1)) +
             dy * ((1 - dx) * at(y1, x0) + dx * at(y1, x1));
  }
  return rgb;
}

void WriteLines(const std::string& path, const std::vector<std::string>& lines) {
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  WriteTextFileAtomically(path, text);
}

// Binary little-endian PLY: float x, y, z; uchar red, green, blue, as nerfstudio writes it
// (colmap_utils.create_ply_from_colmap) and its ply_file_path readers expect: OpenSplat reads
// x, y, z as 4-byte floats whatever the header says, so doubles here became garbage points
// (issue 33: 1,108 of 8,551 Gaussians NaN after 10 steps).
void WritePointsPly(const std::string& path, const std::vector<Eigen::Vector3d>& xyz,
                    const std::vector<std::array<uint8_t, 3>>& rgb) {
  std::string bytes = "ply\nformat binary_little_endian 1.0\nelement vertex " +
                      std::to_string(xyz.size()) +
                      "\nproperty float x\nproperty float y\nproperty float z\n"
                      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                      "end_header\n";
  static_assert(sizeof(float) == 4, "PLY floats are 4 bytes");
  for (size_t i = 0; i < xyz.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const float v = static_cast<float>(xyz[i][k]);
      char raw[4];
      std::memcpy(raw, &v, 4);  // x86-64 and aarch64 are little-endian, as the header says
      bytes.append(raw, 4);
    }
    bytes.append(reinterpret_cast<const char*>(rgb[i].data()), 3);
  }
  WriteTextFileAtomically(path, bytes);
}

void CreateHardLinkOrCopy(const fs::path& from, const fs::path& to) {
  fs::create_directories(to.parent_path());
  std::error_code error;
  fs::create_hard_link(from, to, error);
  if (error) fs::copy_file(from, to, fs::copy_options::overwrite_existing);
}

// Moves the files of `from` into `to` (created) and removes `from`.
void MoveFilesInto(const fs::path& from, const fs::path& to) {
  fs::create_directories(to);
  for (const auto& entry : fs::directory_iterator(from)) {
    // The model writer's record of its folder: the export's own covers the whole.
    if (entry.path().filename() == kWrittenFilesRecord) {
      fs::remove(entry.path());
      continue;
    }
    fs::rename(entry.path(), to / entry.path().filename());
  }
  fs::remove(from);
}

}  // namespace

TrainTestSplit SplitEveryNth(std::vector<std::string> names, int every) {
  if (every < 1) throw std::invalid_argument("SplitEveryNth: every must be >= 1");
  std::sort(names.begin(), names.end());
  TrainTestSplit split;
  for (size_t i = 0; i < names.size(); ++i) {
    (i % static_cast<size_t>(every) == 0 ? split.test : split.train).push_back(names[i]);
  }
  return split;
}

std::vector<MergedTrack> MergeTracks(const TrackObservations& obs,
                                     const std::vector<Eigen::Matrix<double, 3, 4>>& projections,
                                     double max_error_px, TrackMergeSummary* summary) {
  const int n = static_cast<int>(obs.image.size());
  if (obs.points.rows() != n || obs.pixels.rows() != n || obs.colours.rows() != n) {
    throw std::invalid_argument("MergeTracks: observation arrays of different lengths");
  }
  UnionFind sets(n);
  for (Eigen::Index m = 0; m < obs.matches.rows(); ++m) {
    const int a = obs.matches(m, 0), b = obs.matches(m, 1);
    if (a < 0 || a >= n || b < 0 || b >= n) {
      throw std::invalid_argument("MergeTracks: match " + std::to_string(m) +
                                  " names an observation out of range");
    }
    sets.Union(a, b);
  }
  // Members per root, in ascending order; a root is its set's smallest element (UnionFind), so
  // tracks come out in order of their first observation.
  std::vector<std::vector<int>> members(n);
  for (int o = 0; o < n; ++o) members[sets.Find(o)].push_back(o);

  *summary = TrackMergeSummary();
  std::vector<MergedTrack> tracks;
  for (int root = 0; root < n; ++root) {
    const std::vector<int>& track = members[root];
    if (track.size() < 2) continue;
    ++summary->num_tracks;
    std::vector<double> coordinates[3];
    Eigen::Vector3d rgb = Eigen::Vector3d::Zero();
    for (const int o : track) {
      if (obs.points.row(o).allFinite()) {
        for (int k = 0; k < 3; ++k) coordinates[k].push_back(obs.points(o, k));
      }
      rgb += obs.colours.row(o).transpose();
    }
    if (coordinates[0].empty()) {
      ++summary->num_without_ray_time;
      continue;
    }
    MergedTrack merged;
    for (int k = 0; k < 3; ++k) merged.xyz[k] = Median(coordinates[k], kNaN);
    merged.rgb = rgb / static_cast<double>(track.size());
    bool behind = false, disagrees = false;
    double error_sum = 0.0;
    for (const int o : track) {
      const int image = obs.image(o);
      if (image < 0 || image >= static_cast<int>(projections.size())) {
        throw std::invalid_argument("MergeTracks: observation " + std::to_string(o) +
                                    " names image " + std::to_string(image) + " of " +
                                    std::to_string(projections.size()));
      }
      double depth = 0.0;
      const Eigen::Vector2d projected = Project(projections[image], merged.xyz, &depth);
      const double error = (projected - obs.pixels.row(o).transpose()).norm();
      behind = behind || !(depth > 0);
      disagrees = disagrees || !(error <= max_error_px);
      error_sum += error;
    }
    if (behind) {
      ++summary->num_behind_camera;
      continue;
    }
    if (disagrees) {
      ++summary->num_disagreeing;
      continue;
    }
    merged.mean_error_px = error_sum / static_cast<double>(track.size());
    merged.observations = track;
    summary->num_observations_kept += static_cast<int>(track.size());
    tracks.push_back(std::move(merged));
  }
  // Tracks at exactly the same point are one: SIFT gives a keypoint one descriptor per dominant
  // orientation, and the copies, matched alike, come back as separate tracks with bitwise equal
  // points. Merged into the first (observations joined, colours and errors weighted by them); left
  // apart, OpenSplat turned one of such twins into a Gaussian of NaNs within 100 steps (castle-P19,
  // issue 33).
  std::map<std::array<double, 3>, size_t> first_at;
  std::vector<MergedTrack> unique;
  for (MergedTrack& track : tracks) {
    const std::array<double, 3> key = {track.xyz.x(), track.xyz.y(), track.xyz.z()};
    const auto [it, inserted] = first_at.emplace(key, unique.size());
    if (inserted) {
      unique.push_back(std::move(track));
      continue;
    }
    MergedTrack& into = unique[it->second];
    const double a = static_cast<double>(into.observations.size());
    const double b = static_cast<double>(track.observations.size());
    into.rgb = (a * into.rgb + b * track.rgb) / (a + b);
    into.mean_error_px = (a * into.mean_error_px + b * track.mean_error_px) / (a + b);
    into.observations.insert(into.observations.end(), track.observations.begin(),
                             track.observations.end());
    std::sort(into.observations.begin(), into.observations.end());
    ++summary->num_duplicates_merged;
  }
  summary->num_kept = static_cast<int>(unique.size());
  return unique;
}

namespace {

// The pinhole images of the export (`ordered`, name order): one pinhole camera per distorted
// camera in use, numbered in order of first use (splat/undistortion.h); the undistortion's
// scale per camera into *summary.
ImageSet PinholeImagesOf(const std::vector<const ImageInfo*>& ordered, const ImageSet& images,
                         const UndistortionOptions& undistortion, TrainerExportSummary* summary) {
  ImageSet pinhole;
  pinhole.image_root = "images";
  std::map<int, int> pinhole_of_camera;
  for (const ImageInfo* info : ordered) {
    if (info->camera_index < 0 || info->camera_index >= static_cast<int>(images.cameras.size())) {
      throw std::invalid_argument("image " + info->name + " has camera index " +
                                  std::to_string(info->camera_index) + " out of range");
    }
    auto [it, added] =
        pinhole_of_camera.emplace(info->camera_index, static_cast<int>(pinhole.cameras.size()));
    if (added) {
      const CameraIntrinsics& camera = images.cameras[info->camera_index];
      pinhole.cameras.push_back(UndistortedCamera(camera, undistortion));
      summary->undistortion_scale_x.push_back(double(pinhole.cameras.back().width) / camera.width);
      summary->undistortion_scale_y.push_back(double(pinhole.cameras.back().height) /
                                              camera.height);
    }
    const CameraIntrinsics& camera = pinhole.cameras[it->second];
    pinhole.images.push_back({info->name, camera.width, camera.height, it->second});
  }
  return pinhole;
}

// The ray-time source's observations in the exported images (a match counts when both of its
// ends do): their undistorted pixels and ray points (SPEC §3 "Ray point"), the source rows kept and
// each image's rows; colours are filled as the images are read.
struct ExportedObservations {
  TrackObservations tracks;
  std::vector<int> source_rows;            // rows of source.rays kept, in order
  std::vector<std::vector<int>> of_image;  // per exported image, its rows of `tracks`
};

ExportedObservations ObservationsInExport(const RayTimeSource& source,
                                          const std::vector<const ImageInfo*>& ordered,
                                          const std::map<std::string, int>& index_of,
                                          const ImageSet& images, const ImageSet& pinhole) {
  ExportedObservations out;
  out.of_image.resize(ordered.size());
  const RayTimeObservations& rays = source.rays;
  std::vector<int> image_of_row(rays.image_names.size(), -1);
  for (size_t r = 0; r < rays.image_names.size(); ++r) {
    const auto it = index_of.find(rays.image_names[r]);
    if (it != index_of.end() && source.poses.Has(rays.image_names[r])) {
      image_of_row[r] = it->second;
    }
  }
  std::vector<int> kept(rays.observations.rows(), -1);
  for (Eigen::Index o = 0; o < rays.observations.rows(); ++o) {
    const int image = image_of_row[rays.observations(o, 0)];
    if (image < 0) continue;
    kept[o] = static_cast<int>(out.source_rows.size());
    out.of_image[image].push_back(kept[o]);
    out.source_rows.push_back(static_cast<int>(o));
  }
  const auto m = static_cast<Eigen::Index>(out.source_rows.size());
  out.tracks.image.resize(m);
  out.tracks.points.resize(m, 3);
  out.tracks.pixels.resize(m, 2);
  out.tracks.colours.setZero(m, 3);
  for (Eigen::Index k = 0; k < m; ++k) {
    const int o = out.source_rows[k];
    const int image = image_of_row[rays.observations(o, 0)];
    const ImageInfo& info = *ordered[image];
    const CameraIntrinsics& distorted = images.cameras[info.camera_index];
    const CameraIntrinsics& camera = pinhole.cameras[pinhole.images[image].camera_index];
    out.tracks.image(k) = image;
    const Eigen::Vector2d u = UndistortedPixel(distorted, camera, rays.pixels.row(o).transpose());
    out.tracks.pixels.row(k) = u;
    // The ray of the undistorted pixel, X = O + t·R·ray (SPEC §3 "Ray point").
    const double t = rays.ray_times(o);
    if (std::isfinite(t)) {
      const Eigen::Vector3d ray = Eigen::Vector3d((u.x() - camera.cx()) / camera.fx(),
                                                  (u.y() - camera.cy()) / camera.fy(), 1.0)
                                      .normalized();
      const Rigid3& pose = source.poses.world_from_cam.at(info.name);
      out.tracks.points.row(k) = (pose.translation + t * (pose.rotation * ray)).transpose();
    } else {
      out.tracks.points.row(k).setConstant(kNaN);
    }
  }
  std::vector<Eigen::Index> matches;
  for (Eigen::Index r = 0; r < rays.matches.rows(); ++r) {
    const int a = kept[rays.matches(r, 0)], b = kept[rays.matches(r, 1)];
    if (a >= 0 && b >= 0) {
      matches.push_back(a);
      matches.push_back(b);
    }
  }
  out.tracks.matches.resize(static_cast<Eigen::Index>(matches.size() / 2), 2);
  for (size_t i = 0; i < matches.size(); ++i) {
    out.tracks.matches(static_cast<Eigen::Index>(i / 2), static_cast<Eigen::Index>(i % 2)) =
        static_cast<int>(matches[i]);
  }
  return out;
}

// What every pose set's folder shares: the images in name order (ids and the split follow it),
// their pinhole cameras, the split, the solve's observations and the tracks merged from them in
// the solve's frame, with each image's 2D points of those tracks.
struct SharedExport {
  std::vector<const ImageInfo*> ordered;
  std::map<std::string, int> index_of;
  ImageSet pinhole;
  TrainTestSplit split;
  ExportedObservations exported;
  std::vector<MergedTrack> tracks;
  std::vector<std::vector<Eigen::Vector2d>> points2D;
  std::vector<std::vector<uint64_t>> point3D_ids;
  std::vector<std::vector<ColmapTrackElement>> elements;

  int num_images() const { return static_cast<int>(ordered.size()); }
  const CameraIntrinsics& PinholeCamera(int i) const {
    return pinhole.cameras[pinhole.images[i].camera_index];
  }
};

// The images in name order; every pose set must have a pose for each.
std::vector<const ImageInfo*> ImagesInNameOrder(const ImageSet& images,
                                                const std::map<std::string, PoseSet>& poses) {
  std::vector<const ImageInfo*> ordered;
  for (const ImageInfo& info : images.images) ordered.push_back(&info);
  std::sort(ordered.begin(), ordered.end(),
            [](const ImageInfo* a, const ImageInfo* b) { return a->name < b->name; });
  for (const auto& [name, set] : poses) {
    for (const ImageInfo* info : ordered) {
      if (!set.Has(info->name)) {
        throw InputError("export (3dgs): pose set '" + name + "' has no pose for " + info->name);
      }
    }
  }
  return ordered;
}

// The images, once, into `folder` (every pose set's images/ links to it): undistorted (and centred)
// to their pinhole camera, or copied when that is their own camera; the colours of the solve's
// observations read on the way.
void WriteImagesOnce(const ImageSet& images, const std::optional<RayTimeSource>& source,
                     const TrainerExportOptions& options, const fs::path& folder,
                     SharedExport* shared, TrainerExportSummary* summary) {
  TrackObservations& track_obs = shared->exported.tracks;
  const int num_images = shared->num_images();
  auto last_progress = std::chrono::steady_clock::now();
  for (int i = 0; i < num_images; ++i) {
    const ImageInfo& info = *shared->ordered[i];
    const CameraIntrinsics& distorted = images.cameras[info.camera_index];
    const fs::path path = fs::path(images.image_root) / info.name;
    const fs::path target = folder / info.name;
    fs::create_directories(target.parent_path());
    const bool copy = !IsResampled(distorted, shared->PinholeCamera(i));
    const std::vector<int>& observations = shared->exported.of_image[i];
    cv::Mat bgr;
    if (!copy || !observations.empty()) {
      bgr = cv::imread(path.string(), cv::IMREAD_COLOR);
      if (bgr.empty()) ThrowInput(path.string(), 0, "cannot read or decode the image");
      if (bgr.cols != distorted.width || bgr.rows != distorted.height) {
        ThrowInput(path.string(), 0,
                   "image is " + std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows) +
                       " but its camera is " + std::to_string(distorted.width) + "x" +
                       std::to_string(distorted.height));
      }
      for (const int k : observations) {
        const int row = shared->exported.source_rows[k];
        track_obs.colours.row(k) =
            ColourAt(bgr, source->rays.pixels.row(row).transpose()).transpose();
      }
    }
    if (copy) {
      if (!fs::is_regular_file(path)) ThrowInput(path.string(), 0, "image file not found");
      fs::copy_file(path, target);
      ++summary->num_images_copied;
    } else {
      const cv::Mat undistorted = UndistortImage(bgr, distorted, shared->PinholeCamera(i));
      bool written = false;
      try {
        written = cv::imwrite(target.string(), undistorted,
                              {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality});
      } catch (const cv::Exception& e) {
        ThrowInput(target.string(), 0, std::string("cannot encode the image: ") + e.what());
      }
      if (!written) {
        ThrowInput(target.string(), 0, "cannot write the undistorted image (format of its name?)");
      }
      ++summary->num_images_undistorted;
    }
    if (SecondsSince(last_progress) > kProgressSeconds || i + 1 == num_images) {
      last_progress = std::chrono::steady_clock::now();
      spdlog::info(fmt::format("export (3dgs): images {}/{} ({} undistorted, {} copied)", i + 1,
                               num_images, summary->num_images_undistorted,
                               summary->num_images_copied));
    }
  }
}

// The tracks, merged once in the source's frame, and per image its tracks' observations (the same
// 2D points for every pose set).
void MergeSourceTracks(const RayTimeSource& source, const TrainerExportOptions& options,
                       SharedExport* shared, TrainerExportSummary* summary) {
  const int num_images = shared->num_images();
  const TrackObservations& track_obs = shared->exported.tracks;
  std::vector<Eigen::Matrix<double, 3, 4>> projections(num_images,
                                                       Eigen::Matrix<double, 3, 4>::Zero());
  for (int i = 0; i < num_images; ++i) {
    const auto pose = source.poses.world_from_cam.find(shared->ordered[i]->name);
    if (pose == source.poses.world_from_cam.end()) continue;
    projections[i] = ProjectionOf(shared->PinholeCamera(i), pose->second);
  }
  shared->tracks =
      MergeTracks(track_obs, projections, options.max_track_error_px, &summary->tracks);
  summary->points_from = source.pose_set;
  spdlog::info(fmt::format(
      "export (3dgs): {} tracks from the ray times of '{}' ({} observations): {} kept, {} "
      "disagreeing beyond {} px, {} behind a camera, {} without a ray time, {} at another's point "
      "merged into it",
      summary->tracks.num_tracks, source.pose_set, track_obs.image.size(), summary->tracks.num_kept,
      summary->tracks.num_disagreeing, options.max_track_error_px,
      summary->tracks.num_behind_camera, summary->tracks.num_without_ray_time,
      summary->tracks.num_duplicates_merged));

  shared->points2D.assign(num_images, {});
  shared->point3D_ids.assign(num_images, {});
  shared->elements.assign(shared->tracks.size(), {});
  for (size_t t = 0; t < shared->tracks.size(); ++t) {
    for (const int o : shared->tracks[t].observations) {
      const int image = track_obs.image(o);
      shared->elements[t].push_back({static_cast<uint32_t>(image + 1),
                                     static_cast<uint32_t>(shared->points2D[image].size())});
      shared->points2D[image].push_back(track_obs.pixels.row(o).transpose() +
                                        Eigen::Vector2d(0.5, 0.5));  // COLMAP convention
      shared->point3D_ids[image].push_back(t + 1);
    }
  }
}

// transforms.json's split lists and point cloud.
nlohmann::json TransformsExtras(const TrainTestSplit& split, bool with_points) {
  nlohmann::json extras = {{"train_filenames", nlohmann::json::array()},
                           {"test_filenames", nlohmann::json::array()}};
  for (const std::string& name : split.train) extras["train_filenames"].push_back("images/" + name);
  for (const std::string& name : split.test) extras["test_filenames"].push_back("images/" + name);
  // nerfstudio's parser refuses a transforms.json that lists some splits but not the one asked
  // for, and ns-train asks for "val": the held-out images serve as both.
  extras["val_filenames"] = extras["test_filenames"];
  if (with_points) extras["ply_file_path"] = "sparse_pc.ply";
  return extras;
}

// The frame the points take in pose set `name`: "solve" (the source's own), "sim3" (mapped onto
// its centres by `to_set`), or "none" (no points: none merged, or no Sim(3), which is warned).
std::string PointsFrame(const std::string& name, const PoseSet& set,
                        const std::optional<RayTimeSource>& source, const SharedExport& shared,
                        Warnings* warnings, Sim3* to_set) {
  if (!source || shared.tracks.empty()) return "none";
  if (name == source->pose_set) return "solve";
  std::vector<Eigen::Vector3d> from, to;
  for (const ImageInfo* info : shared.ordered) {
    const auto pose = source->poses.world_from_cam.find(info->name);
    if (pose == source->poses.world_from_cam.end()) continue;
    from.push_back(pose->second.translation);
    to.push_back(set.world_from_cam.at(info->name).translation);
  }
  try {
    *to_set = FitAlignment(from, to, AlignmentKind::kSim3);
    return "sim3";
  } catch (const std::invalid_argument&) {
    warnings->push_back({"no_initial_points",
                         "the 3dgs export of '" + name +
                             "' has no initial points: no Sim(3) maps the " +
                             std::to_string(from.size()) + " camera centres of '" +
                             source->pose_set + "' onto its own (fewer than three, or collinear)",
                         {},
                         {},
                         {{"pose_set", name}, {"points_from", source->pose_set}}});
    spdlog::warn(fmt::format("export (3dgs): {}", warnings->back().message));
    return "none";
  }
}

// A pose set's points: the merged tracks in its frame (`to_set`), into its COLMAP model and PLY,
// with every observation's reprojection error in it.
struct PoseSetPoints {
  std::vector<Eigen::Vector3d> xyz;
  std::vector<std::array<uint8_t, 3>> rgb;
  std::vector<double> errors;
};

PoseSetPoints AddPoints(const SharedExport& shared, const PoseSet& set, const Sim3& to_set,
                        ColmapModel* model) {
  std::vector<Eigen::Matrix<double, 3, 4>> projections;
  for (int i = 0; i < shared.num_images(); ++i) {
    projections.push_back(
        ProjectionOf(shared.PinholeCamera(i), set.world_from_cam.at(shared.ordered[i]->name)));
  }
  for (int i = 0; i < shared.num_images(); ++i) {
    ColmapImage& image = model->images.at(static_cast<uint32_t>(i + 1));
    image.points2D = shared.points2D[i];
    image.point3D_ids = shared.point3D_ids[i];
  }
  const TrackObservations& track_obs = shared.exported.tracks;
  PoseSetPoints out;
  for (size_t t = 0; t < shared.tracks.size(); ++t) {
    ColmapPoint3D point;
    point.point3D_id = t + 1;
    point.xyz = to_set * shared.tracks[t].xyz;
    std::array<uint8_t, 3> rgb;
    for (int k = 0; k < 3; ++k) {
      rgb[k] = static_cast<uint8_t>(std::clamp(std::lround(shared.tracks[t].rgb[k]), 0L, 255L));
      point.rgb[k] = rgb[k];
    }
    double sum = 0.0;
    for (const int o : shared.tracks[t].observations) {
      double depth = 0.0;
      const double error = (Project(projections[track_obs.image(o)], point.xyz, &depth) -
                            track_obs.pixels.row(o).transpose())
                               .norm();
      out.errors.push_back(error);
      sum += error;
    }
    point.error = sum / static_cast<double>(shared.tracks[t].observations.size());
    point.track = shared.elements[t];
    model->points3D[point.point3D_id] = point;
    out.xyz.push_back(point.xyz);
    out.rgb.push_back(rgb);
  }
  return out;
}

// One pose set's folder, written whole or not at all: images/ (links into `images`), sparse/0
// (text and binary), transforms.json, sparse_pc.ply (with points), train.txt and test.txt.
std::string WritePoseSetFolder(const std::string& root, const std::string& name, const PoseSet& set,
                               const SharedExport& shared,
                               const std::optional<RayTimeSource>& source, const fs::path& images,
                               const nlohmann::json& frame_fields, Warnings* warnings,
                               TrainerExportSummary* summary) {
  Sim3 to_set;
  const std::string frame = PointsFrame(name, set, source, shared, warnings, &to_set);
  ColmapModel model = ToColmapModel(shared.pinhole, set);
  const PoseSetPoints points =
      frame == "none" ? PoseSetPoints() : AddPoints(shared, set, to_set, &model);
  summary->points_frame[name] = frame;
  summary->reprojection_median_px[name] = Median(points.errors, 0.0);
  const nlohmann::json extras = TransformsExtras(shared.split, frame != "none");

  const std::string dir = (fs::path(root) / name).string();
  WriteDirectoryAtomically(dir, [&](const std::string& tmp) {
    for (const ImageInfo* info : shared.ordered) {
      CreateHardLinkOrCopy(images / info->name, fs::path(tmp) / "images" / info->name);
    }
    const fs::path sparse = fs::path(tmp) / "sparse";
    WriteColmapModelText(model, (sparse / "text").string());
    WriteColmapModelBinary(model, (sparse / "binary").string());
    MoveFilesInto(sparse / "text", sparse / "0");
    MoveFilesInto(sparse / "binary", sparse / "0");
    WriteTransformsJson((fs::path(tmp) / "transforms.json").string(), shared.pinhole, set,
                        "images/", extras, frame_fields);
    if (frame != "none") {
      WritePointsPly((fs::path(tmp) / "sparse_pc.ply").string(), points.xyz, points.rgb);
    }
    WriteLines((fs::path(tmp) / "test.txt").string(), shared.split.test);
    WriteLines((fs::path(tmp) / "train.txt").string(), shared.split.train);
  });
  spdlog::info(fmt::format(
      "export (3dgs): {} -> {}: {} images ({} train, {} test), {} points ({}), median "
      "reprojection {:.3g} px",
      name, dir, shared.num_images(), shared.split.train.size(), shared.split.test.size(),
      model.points3D.size(), frame, summary->reprojection_median_px[name]));
  return dir;
}

// A temporary folder next to `path`, removed however the export ends.
struct TemporaryFolder {
  explicit TemporaryFolder(const std::string& path) : path(TemporarySibling(path)) {
    RegisterTemporary(this->path.string());
    fs::create_directories(this->path);
  }
  ~TemporaryFolder() {
    std::error_code ignored;
    fs::remove_all(path, ignored);
    ForgetTemporary(path.string());
  }
  fs::path path;
};

}  // namespace

TrainerExportSummary ExportForTrainers(const ImageSet& images,
                                       const std::map<std::string, PoseSet>& poses,
                                       const std::optional<RayTimeSource>& source,
                                       const TrainerExportOptions& options, const std::string& root,
                                       Warnings* warnings,
                                       const std::map<std::string, nlohmann::json>& frame_fields) {
  const auto start = std::chrono::steady_clock::now();
  ValidateOptions(options, "export (3dgs)");
  if (images.images.empty()) throw InputError("export (3dgs): no image to export");
  TrainerExportSummary summary;

  SharedExport shared;
  shared.ordered = ImagesInNameOrder(images, poses);
  std::vector<std::string> names;
  for (int i = 0; i < shared.num_images(); ++i) {
    shared.index_of[shared.ordered[i]->name] = i;
    names.push_back(shared.ordered[i]->name);
  }
  shared.split = SplitEveryNth(names, options.test_every);
  shared.pinhole = PinholeImagesOf(shared.ordered, images, options.undistortion, &summary);
  shared.exported.of_image.resize(shared.num_images());
  if (source) {
    shared.exported =
        ObservationsInExport(*source, shared.ordered, shared.index_of, images, shared.pinhole);
  }

  fs::create_directories(root);
  const TemporaryFolder image_folder((fs::path(root) / "images").string());
  WriteImagesOnce(images, source, options, image_folder.path, &shared, &summary);
  if (source) MergeSourceTracks(*source, options, &shared, &summary);
  for (const auto& [name, all_poses] : poses) {
    PoseSet set;  // the exported images' poses only
    for (const ImageInfo* info : shared.ordered) {
      set.world_from_cam[info->name] = all_poses.world_from_cam.at(info->name);
    }
    summary.directories.push_back(WritePoseSetFolder(
        root, name, set, shared, source, image_folder.path,
        frame_fields.count(name) ? frame_fields.at(name) : nlohmann::json::object(), warnings,
        &summary));
    summary.pose_sets.push_back(name);
  }
  if (!source) {
    warnings->push_back({"no_initial_points",
                         "the 3dgs export has no initial points (no refined solve's ray times); "
                         "trainers start from their own initialization",
                         {},
                         {},
                         {}});
    spdlog::warn(fmt::format("export (3dgs): {}", warnings->back().message));
  }
  summary.num_images = shared.num_images();
  summary.num_points = static_cast<int>(shared.tracks.size());
  summary.num_train = static_cast<int>(shared.split.train.size());
  summary.num_test = static_cast<int>(shared.split.test.size());
  summary.seconds = SecondsSince(start);
  return summary;
}

bool TrainerDerivedPath(const std::string& relative) {
  const fs::path path(relative);
  if (path.empty()) return false;
  return path == fs::path("sparse/0/points3D.ply") ||
         path.begin()->string().rfind("images_", 0) == 0;
}

}  // namespace raytime

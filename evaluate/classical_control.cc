#include "evaluate/classical_control.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <regex>
#include <sstream>

#include "core/camera.h"
#include "core/error.h"
#include "core/options.h"
#include "core/process.h"
#include "core/timing.h"
#include "formats/colmap_database.h"
#include "formats/colmap_model.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

// An option value as text with 17 significant digits, so COLMAP receives the threshold unchanged.
std::string Number(double value) {
  std::ostringstream out;
  out.precision(17);
  out << value;
  return out.str();
}

// Runs COLMAP with stdout and stderr appended to `log_path`; returns the text it appended.
// COLMAP links Qt; without a display its platform plugin must be the offscreen one (PLATFORM.md),
// unless the caller's environment chose one.
std::string RunColmap(const std::vector<std::string>& argv, const std::string& log_path) {
  const std::string command = CommandLine(argv);
  const auto offset = fs::exists(log_path) ? fs::file_size(log_path) : 0;
  {
    std::ofstream log(log_path, std::ios::app);
    log << "\n$ " << command << "\n";
  }
  ProcessOptions options;
  options.output_path = log_path;
  options.default_environment = {"QT_QPA_PLATFORM=offscreen"};
  pid_t pid = 0;
  try {
    pid = StartProcess(argv, options);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string(e.what()) +
                             " (is COLMAP 3.8 installed? option 'colmap' names the executable)");
  }
  const ProcessStatus status = WaitProcess(pid);
  if (!status.Succeeded()) {
    throw std::runtime_error("COLMAP command failed (" + status.Describe() + "): " + command +
                             "; its output is in " + log_path);
  }
  std::ifstream log(log_path, std::ios::binary);
  log.seekg(static_cast<std::streamoff>(offset));
  std::ostringstream text;
  text << log.rdbuf();
  return text.str();
}

// The last "Final cost : X [px]" of COLMAP's bundle adjustment report in `output`, or NaN.
double LastFinalCost(const std::string& output) {
  static const std::regex pattern(R"(Final cost\s*:\s*([0-9.eE+-]+)\s*\[px\])");
  double cost = std::numeric_limits<double>::quiet_NaN();
  for (auto it = std::sregex_iterator(output.begin(), output.end(), pattern);
       it != std::sregex_iterator(); ++it) {
    cost = std::stod((*it)[1].str());
  }
  return cost;
}

// The gate options shared by point_triangulator and mapper (COLMAP's IncrementalMapper options).
std::vector<std::string> GateArguments(const ClassicalControlOptions& o) {
  return {"--Mapper.tri_create_max_angle_error",
          Number(o.max_angle_error_deg),
          "--Mapper.tri_continue_max_angle_error",
          Number(o.max_angle_error_deg),
          "--Mapper.tri_merge_max_reproj_error",
          Number(o.max_reproj_error_px),
          "--Mapper.tri_complete_max_reproj_error",
          Number(o.max_reproj_error_px),
          "--Mapper.filter_max_reproj_error",
          Number(o.max_reproj_error_px),
          "--Mapper.tri_min_angle",
          Number(o.min_tri_angle_deg),
          "--Mapper.filter_min_tri_angle",
          Number(o.min_tri_angle_deg)};
}

std::vector<std::string> Concat(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

std::string Flag(bool value) { return value ? "1" : "0"; }

// Mean reprojection error over every track element, with the model's own cameras.
double MeanReprojectionError(const ColmapModel& model, int* num_observations) {
  std::map<uint32_t, CameraIntrinsics> intrinsics;
  for (const auto& [id, camera] : model.cameras) intrinsics[id] = IntrinsicsFromColmap(camera);
  double sum = 0.0;
  int count = 0;
  for (const auto& [id, point] : model.points3D) {
    for (const ColmapTrackElement& element : point.track) {
      const ColmapImage& image = model.images.at(element.image_id);
      const double* k = intrinsics.at(image.camera_id).params.data();
      const Eigen::Vector3d p = image.cam_from_world * point.xyz;
      double undistorted[2], distorted[2];
      ProjectPinhole(k, p.data(), undistorted);
      DistortPixel(k, undistorted, distorted);
      // points2D are in COLMAP's pixel convention; the intrinsics in OpenCV's.
      const Eigen::Vector2d observed =
          image.points2D.at(element.point2D_idx) - Eigen::Vector2d(0.5, 0.5);
      sum += (Eigen::Vector2d(distorted[0], distorted[1]) - observed).norm();
      ++count;
    }
  }
  *num_observations = count;
  return count ? sum / count : std::numeric_limits<double>::quiet_NaN();
}

// JSON has no NaN: the costs COLMAP's log did not report become null.
void NullNonFinite(nlohmann::json* value) {
  if (value->is_number_float() && !std::isfinite(value->get<double>())) *value = nullptr;
  if (value->is_structured()) {
    for (nlohmann::json& child : *value) NullNonFinite(&child);
  }
}

// The model folder of a mapper run with the most registered images.
std::string LargestMapperModel(const std::string& mapper_dir, const std::string& log_path) {
  std::string best;
  size_t best_images = 0;
  for (const auto& entry : fs::directory_iterator(mapper_dir)) {
    if (!entry.is_directory()) continue;
    const size_t n = ReadColmapModel(entry.path().string()).images.size();
    if (n > best_images || (n == best_images && entry.path().string() < best)) {
      best = entry.path().string();
      best_images = n;
    }
  }
  if (best.empty()) {
    throw std::runtime_error("COLMAP's mapper reconstructed nothing in " + mapper_dir +
                             "; its output is in " + log_path);
  }
  return best;
}

// COLMAP's mapper (incremental SfM, no prior) on the database: one "round", the largest model.
void RunMapper(const ClassicalControlOptions& options, const std::vector<std::string>& io,
               const std::string& workdir, ClassicalControlSummary* result) {
  const std::string refine = Flag(options.refine_intrinsics);
  const std::string mapper_dir = (fs::path(workdir) / "mapper").string();
  fs::create_directories(mapper_dir);
  const auto t = std::chrono::steady_clock::now();
  const std::string output = RunColmap(
      Concat(Concat(Concat({options.colmap, "mapper"}, io), {"--output_path", mapper_dir}),
             Concat(GateArguments(options), {"--Mapper.ba_refine_focal_length", refine,
                                             "--Mapper.ba_refine_principal_point", refine,
                                             "--Mapper.ba_refine_extra_params", refine})),
      result->log_path);
  ClassicalRoundSummary round_summary;
  round_summary.triangulate_s = SecondsSince(t);
  round_summary.colmap_final_cost_px = LastFinalCost(output);
  result->model_dir = LargestMapperModel(mapper_dir, result->log_path);
  result->per_round.push_back(round_summary);
}

// options.rounds of point_triangulator + bundle_adjuster from the prior, each from the last one's
// adjusted model.
void RunTriangulateAdjustRounds(const ImageSet& images, const PoseSet& prior,
                                const ClassicalControlOptions& options,
                                const std::vector<std::string>& io, const std::string& workdir,
                                ClassicalControlSummary* result) {
  const std::string refine = Flag(options.refine_intrinsics);
  // The prior as a model with no points; ids agree with the database (ToColmapModel).
  ColmapModel prior_model = ToColmapModel(images, prior);
  if (prior_model.images.size() < 2) {
    throw InputError("the classical control needs a prior pose for at least two images (" +
                     std::to_string(prior_model.images.size()) + " of " +
                     std::to_string(images.images.size()) + " have one)");
  }
  if (options.refine_intrinsics) {
    // ToColmapModel's camera ids are camera_index + 1.
    for (auto& [id, camera] : prior_model.cameras) {
      camera = ColmapCameraWithModel(images.cameras[id - 1], id, "OPENCV");
    }
  }
  std::string input = (fs::path(workdir) / "prior").string();
  WriteColmapModelText(prior_model, input);
  for (int r = 1; r <= options.rounds; ++r) {
    const fs::path round_dir = fs::path(workdir) / ("round_" + std::to_string(r));
    const std::string triangulated = (round_dir / "triangulated").string();
    const std::string adjusted = (round_dir / "adjusted").string();
    fs::create_directories(triangulated);
    fs::create_directories(adjusted);
    ClassicalRoundSummary round_summary;
    auto t = std::chrono::steady_clock::now();
    RunColmap(Concat(Concat(Concat({options.colmap, "point_triangulator"}, io),
                            {"--input_path", input, "--output_path", triangulated}),
                     GateArguments(options)),
              result->log_path);
    round_summary.triangulate_s = SecondsSince(t);
    t = std::chrono::steady_clock::now();
    const std::string output =
        RunColmap({options.colmap, "bundle_adjuster", "--input_path", triangulated, "--output_path",
                   adjusted, "--BundleAdjustment.refine_focal_length", refine,
                   "--BundleAdjustment.refine_principal_point", refine,
                   "--BundleAdjustment.refine_extra_params", refine},
                  result->log_path);
    round_summary.adjust_s = SecondsSince(t);
    round_summary.colmap_final_cost_px = LastFinalCost(output);
    round_summary.num_points = static_cast<int>(ReadColmapModel(adjusted).points3D.size());
    result->per_round.push_back(round_summary);
    input = adjusted;
  }
  result->model_dir = input;
}

}  // namespace

ClassicalControlOptions ClassicalControlOptions::Tuned() {
  ClassicalControlOptions options;
  options.rounds = 8;
  options.max_angle_error_deg = 8.0;
  options.max_reproj_error_px = 16.0;
  return options;
}

nlohmann::json ClassicalControlSummary::ToJson() const {
  nlohmann::json out = *this;
  NullNonFinite(&out);
  return out;
}

PoseSet RunClassicalControl(const std::string& database_path, const ImageSet& images,
                            const PoseSet& prior, const ClassicalControlOptions& options,
                            const std::string& workdir, ClassicalControlSummary* summary) {
  ValidateOptions(options, "classical control");
  const auto start = std::chrono::steady_clock::now();
  if (!fs::is_regular_file(database_path)) {
    ThrowInput(database_path, 0, "no such file (COLMAP database for the classical control)");
  }
  if (images.image_root.empty() || !fs::is_directory(images.image_root)) {
    const std::string root = "'" + images.image_root + "'";
    throw InputError("the classical control needs the image folder for COLMAP; image root " + root +
                     " is not a folder");
  }
  ClassicalControlSummary result;
  result.mode = options.mode;
  result.num_images = static_cast<int>(images.images.size());

  // A fresh work area: COLMAP output from an earlier run must not leak into this one.
  fs::create_directories(workdir);
  for (const auto& entry : fs::directory_iterator(workdir)) {
    const std::string name = entry.path().filename().string();
    if (name == "prior" || name == "mapper" || name.rfind("round_", 0) == 0) {
      fs::remove_all(entry.path());
    }
  }
  result.log_path = (fs::path(workdir) / "colmap.log").string();
  std::ofstream(result.log_path, std::ios::trunc);
  const std::vector<std::string> io = {"--database_path", database_path, "--image_path",
                                       images.image_root};

  if (options.mode == "mapper") {
    RunMapper(options, io, workdir, &result);
  } else {
    RunTriangulateAdjustRounds(images, prior, options, io, workdir, &result);
  }

  const ColmapModel model = ReadColmapModel(result.model_dir);
  PoseSet poses;
  FromColmapModel(model, nullptr, &poses);
  result.rounds = static_cast<int>(result.per_round.size());
  result.num_registered = static_cast<int>(poses.size());
  result.num_points = static_cast<int>(model.points3D.size());
  result.mean_reprojection_error_px = MeanReprojectionError(model, &result.num_observations);
  result.colmap_final_cost_px = result.per_round.back().colmap_final_cost_px;
  if (options.mode == "mapper") result.per_round.back().num_points = result.num_points;
  result.wall_time_s = SecondsSince(start);
  if (summary) *summary = result;
  return poses;
}

}  // namespace raytime

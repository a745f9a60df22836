// capture_fixture_tool: a phone-capture folder made from a Strecha scene, for the end-to-end runs
// of issue 10 (bench/capture_fixture_e2e.sh). Test-only (it uses the fixture writers of
// tests/capture_fixtures.h and reads the scene's ground truth); never part of the libraries.
//
//   capture_fixture_tool --scene SCENE --format record3d|polycam|stray --out FOLDER
//       [--level-deg 8] [--seed 0] [--prior-model DIR] [--gt DIR] [--fps 10] [--odometry-hz 30]
//       [--codec mp4v]
//
// The app's poses are the scene's ground truth perturbed by the ladder protocol
// (configs/ladder.yaml: i.i.d. per frame by exactly level_deg about a random axis and level_deg
// x 1.25 % of the median camera-to-scene distance, evaluate/perturbation.h; the same draws as
// `prior: {source: perturb, mode: iid, level_deg: L, seed: S}` on the scene), the intrinsics the
// scene's K; frame i is the scene's image i in name order, at time 1000 + i / fps s. FOLDER gets
// the images (or the video) and the app's poses only, no ground truth.
//   --prior-model DIR  the same poses as a COLMAP text model named as the scene's images (the
//                      reference arm: the scene as dataset, prior.source file)
//   --gt DIR           the scene's ground truth under the capture's image names, as a Strecha
//                      layout of symbolic links to the scene's files (for `raytime evaluate
//                      --gt DIR --gt_format strecha`), outside FOLDER
//   stray: rgb.mp4 at --fps (--codec: 'mp4v' MPEG-4 Part 2, 'avc1' H.264), odometry.csv at
//          --odometry-hz from the first frame's time to the last's, camera_matrix.csv at the
//          video's size.
// Prints a JSON summary (frames, names, perturbation) on stdout.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "evaluate/perturbation.h"
#include "formats/colmap_model.h"
#include "formats/strecha.h"
#include "tests/capture_fixtures.h"

namespace fs = std::filesystem;
using namespace raytime;

namespace {

std::string FrameName(const std::string& format, int i, double time_s) {
  char name[64];
  if (format == "record3d") return std::to_string(i) + ".jpg";
  if (format == "polycam") return std::to_string(std::llround(time_s * 1e6)) + ".jpg";
  std::snprintf(name, sizeof(name), "frame_%06d.jpg", i);  // stray: decoded frame i
  return name;
}

void Link(const fs::path& target, const fs::path& link) {
  fs::create_directories(link.parent_path());
  std::error_code ignored;
  fs::remove(link, ignored);
  fs::create_symlink(fs::absolute(target), link);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "A phone-capture folder (images + the app's poses, no ground truth) from a Strecha "
      "scene, the poses perturbed by the ladder protocol"};
  std::string scene, format, out, prior_model, gt, codec = "mp4v";
  double level_deg = 8, fps = 10, odometry_hz = 30;
  int seed = 0;
  app.add_option("--scene", scene, "Strecha scene root (images/, gt_dense_cameras/)")->required();
  app.add_option("--format", format, "record3d, polycam or stray")
      ->required()
      ->check(CLI::IsMember({"record3d", "polycam", "stray"}));
  app.add_option("--out", out, "Capture folder to write (must not exist)")->required();
  app.add_option("--level-deg", level_deg, "Perturbation level, degrees");
  app.add_option("--seed", seed, "Perturbation seed");
  app.add_option("--prior-model", prior_model, "Also write the poses as a COLMAP text model here");
  app.add_option("--gt", gt, "Also write the ground truth under the capture's names here");
  app.add_option("--fps", fps, "Frame rate (stray: the video's; others: the timestamps')");
  app.add_option("--odometry-hz", odometry_hz, "stray: rate of odometry.csv");
  app.add_option("--codec", codec, "stray: video codec, OpenCV fourcc (mp4v, avc1)");
  CLI11_PARSE(app, argc, argv);
  if (fs::exists(out)) {
    std::cerr << out << " exists; give a new folder\n";
    return 2;
  }

  ImageSet images;
  PoseSet ground_truth;
  ReadStrechaScene(scene, &images, &ground_truth);
  PerturbationOptions perturbation;
  perturbation.mode = "iid";
  perturbation.level_deg = level_deg;
  perturbation.seed = seed;
  PerturbationSummary perturbation_summary;
  const PoseSet prior = PerturbPoses(ground_truth, perturbation, &perturbation_summary);

  fixtures::Capture capture;
  capture.width = images.images.front().width;
  capture.height = images.images.front().height;
  nlohmann::json frames = nlohmann::json::array();
  for (size_t i = 0; i < images.images.size(); ++i) {
    const ImageInfo& image = images.images[i];
    if (image.width != capture.width || image.height != capture.height) {
      std::cerr << image.name << ": every image must have the first one's size\n";
      return 2;
    }
    const CameraIntrinsics& camera = images.cameras[image.camera_index];
    if (camera.HasDistortion()) {
      std::cerr << image.name << ": the capture formats have no distortion\n";
      return 2;
    }
    fixtures::Frame frame;
    frame.image = (fs::path(images.image_root) / image.name).string();
    frame.world_from_cam = prior.world_from_cam.at(image.name);
    frame.K << camera.fx(), 0, camera.cx(), 0, camera.fy(), camera.cy(), 0, 0, 1;
    frame.time_s = 1000.0 + static_cast<double>(i) / fps;
    capture.frames.push_back(frame);
    frames.push_back({{"scene_name", image.name},
                      {"capture_name", FrameName(format, static_cast<int>(i), frame.time_s)},
                      {"time_s", frame.time_s}});
  }

  nlohmann::json summary = {{"scene", scene},
                            {"format", format},
                            {"out", out},
                            {"level_deg", level_deg},
                            {"seed", seed},
                            {"translation_m", perturbation_summary.translation_m},
                            {"scene_distance_m", perturbation_summary.scene_distance_m},
                            {"num_frames", capture.frames.size()},
                            {"frames", frames}};
  if (format == "record3d") {
    fixtures::WriteRecord3d(capture, out);
  } else if (format == "polycam") {
    fixtures::WritePolycam(capture, out);
  } else {
    std::vector<fixtures::OdometryRow> rows;
    if (!fixtures::WriteStray(capture, out, fps, odometry_hz, 1.0, &rows, codec)) {
      std::cerr << "this OpenCV cannot write a '" << codec << "' video\n";
      return 1;
    }
    summary["codec"] = codec;
    summary["fps"] = fps;
    summary["odometry_hz"] = odometry_hz;
    summary["num_odometry_rows"] = rows.size();
  }

  if (!prior_model.empty()) {
    WriteColmapModelText(ToColmapModel(images, prior), prior_model);
    summary["prior_model"] = prior_model;
  }
  if (!gt.empty()) {
    for (const auto& frame : frames) {
      const std::string scene_name = frame["scene_name"], capture_name = frame["capture_name"];
      Link(fs::path(scene) / "images" / scene_name, fs::path(gt) / "images" / capture_name);
      Link(fs::path(scene) / "gt_dense_cameras" / (scene_name + ".camera"),
           fs::path(gt) / "gt_dense_cameras" / (capture_name + ".camera"));
    }
    summary["gt"] = gt;
  }
  std::cout << summary.dump(2) << std::endl;
  return 0;
}

// The splat stage end to end (issue 11, must-show "the hook end to end on the sample"): the raytime
// binary runs a pipeline on the sample scene with one splat stage per trainer kind over the pose
// sets prior, refined and ground_truth. The trainer is tests/splat_standin.sh, which writes every
// trainer's real output format with known numbers; one pose set's trainer crashes (gsplat) and
// one writes no metrics (nerfstudio). The trainer-ready exports (WORKDIR/3dgs/<pose set>, export
// format 3dgs) are a fixture made here: tiny images and minimal COLMAP models, transforms.json and
// test.txt in the layout the export writes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "core/types.h"
#include "formats/colmap_model.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

const std::vector<std::string> kPoseSets = {"prior", "refined", "ground_truth"};

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

json ReadJson(const fs::path& path) { return json::parse(ReadFile(path)); }

int CountLines(const std::string& text, const std::string& line) {
  int count = 0;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) count += l == line ? 1 : 0;
  return count;
}

// WORKDIR/3dgs/<pose set>/ as the export format 3dgs lays it out: images/, sparse/0/ (text and
// binary), transforms.json, test.txt. Two 16x16 images, one PINHOLE camera, no points.
void WriteExportFixture(const fs::path& dir) {
  fs::create_directories(dir / "images");
  ImageSet images;
  CameraIntrinsics camera;
  camera.width = camera.height = 16;
  camera.params = {20, 20, 7.5, 7.5, 0, 0, 0, 0};
  images.cameras = {camera};
  PoseSet poses;
  for (int i = 0; i < 2; ++i) {
    const std::string name = "000" + std::to_string(i) + ".png";
    images.images.push_back({name, 16, 16, 0});
    Rigid3 pose;
    pose.translation = Eigen::Vector3d(0.1 * i, 0, 0);
    poses.world_from_cam[name] = pose;
    ASSERT_TRUE(cv::imwrite((dir / "images" / name).string(),
                            cv::Mat(16, 16, CV_8UC3, cv::Scalar(40 * i, 90, 200))));
  }
  const ColmapModel model = ToColmapModel(images, poses);
  WriteColmapModelText(model, (dir / "sparse/0").string());
  WriteColmapModelBinary(model, (dir / "bin").string());
  for (const auto& entry : fs::directory_iterator(dir / "bin")) {
    fs::rename(entry.path(), dir / "sparse/0" / entry.path().filename());
  }
  fs::remove(dir / "bin");
  std::ofstream(dir / "transforms.json")
      << R"({"camera_model": "OPENCV", "fl_x": 20, "fl_y": 20, "cx": 8, "cy": 8, "w": 16,)"
      << R"( "h": 16, "k1": 0, "k2": 0, "p1": 0, "p2": 0, "frames": [)"
      << R"({"file_path": "images/0000.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},)"
      << R"({"file_path": "images/0001.png", "transform_matrix": [[1,0,0,0.1],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}],)"
      << R"( "train_filenames": ["images/0001.png"], "val_filenames": ["images/0000.png"],)"
      << R"( "test_filenames": ["images/0000.png"]})";
  std::ofstream(dir / "test.txt") << "0000.png\n";
}

// The stand-in's held-out renders: ground truth grey 100, render grey 108 everywhere, so
// raytime's PSNR is 20 log10(255 / 8) and its SSIM that of two constant images,
// (2ab + C1) / (a^2 + b^2 + C1).
void WriteRenderFixture(const fs::path& dir) {
  fs::create_directories(dir);
  const cv::Mat gt(16, 16, CV_8UC3, cv::Scalar(100, 100, 100));
  const cv::Mat render(16, 16, CV_8UC3, cv::Scalar(108, 108, 108));
  cv::Mat side;
  cv::hconcat(gt, render, side);
  ASSERT_TRUE(cv::imwrite((dir / "gt.png").string(), gt));
  ASSERT_TRUE(cv::imwrite((dir / "render.png").string(), render));
  ASSERT_TRUE(cv::imwrite((dir / "side.png").string(), side));
}

const double kRaytimePsnr = 20.0 * std::log10(255.0 / 8.0);
const double kRaytimeSsim = [] {
  const double a = 100.0 / 255.0, b = 108.0 / 255.0, c1 = 1e-4;
  return (2 * a * b + c1) / (a * a + b * b + c1);
}();

// The stand-in's numbers (tests/splat_standin.sh): trainer tag -> pose set -> PSNR, SSIM, LPIPS.
struct Known {
  double psnr, ssim, lpips;
};
const std::map<std::string, std::map<std::string, Known>> kKnown = {
    {"gsplat",
     {{"prior", {20.5, 0.625, 0.375}},
      {"refined", {22.25, 0.75, 0.25}},
      {"ground_truth", {23.0, 0.8125, 0.1875}}}},
    {"inria",
     {{"prior", {20.25, 0.5, 0.5}},
      {"refined", {22.0, 0.625, 0.375}},
      {"ground_truth", {22.75, 0.6875, 0.25}}}},
    {"nerfstudio",
     {{"prior", {20.75, 0.6875, 0.3125}},
      {"refined", {22.5, 0.8125, 0.1875}},
      {"ground_truth", {23.25, 0.875, 0.125}}}}};

std::string StandIn(const std::string& tag, const fs::path& fixture) {
  return "sh " + std::string(RAYTIME_SOURCE_DIR) + "/tests/splat_standin.sh " + tag +
         " {pose_set} {result_dir} {data_dir} " + fixture.string();
}

class SplatStageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    WriteRenderFixture(fixture_);
    for (const auto& pose_set : kPoseSets) WriteExportFixture(work_ / "3dgs" / pose_set);
    // gsplat crashes on the refined poses; nerfstudio trains on the ground truth but writes no
    // metrics.
    std::ofstream(fixture_ / "fail_gsplat_refined") << "";
    std::ofstream(fixture_ / "nometrics_nerfstudio_ground_truth") << "";
    std::ofstream(pipeline_) << "name: splat-test\n"
                                "dataset: {format: strecha, root: data/sample/fountain-P11}\n"
                                "stages:\n"
                                "  - prior: {source: perturb, level_deg: 4, seed: 0}\n"
                             << Stage("gsplat") << Stage("inria") << Stage("nerfstudio");
  }

  // A splat stage per trainer kind, the stand-in tagged with the trainer's name.
  std::string Stage(const std::string& trainer) const {
    return "  - splat@" + trainer + ": {trainer: " + trainer +
           ", poses: [prior, refined, ground_truth], command: \"" + StandIn(trainer, fixture_) +
           "\"}\n";
  }

  CommandResult Run() {
    return RunRaytime("run " + pipeline_.string() + " --workdir " + work_.string());
  }

  TempDir dir_{"splat_stage"};
  fs::path work_ = dir_.path() / "work";
  fs::path fixture_ = dir_.path() / "fixture";
  fs::path pipeline_ = dir_.path() / "splat.yaml";
};

TEST_F(SplatStageTest, EachTrainerKindIsReadBackAndAFailedPoseSetKeepsTheOthers) {
  const CommandResult run = Run();
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const json summary = ReadJson(work_ / "summary.json");
  EXPECT_EQ(summary["status"], "ok_with_warnings");
  for (const auto& [trainer, by_pose_set] : kKnown) {
    for (const auto& [pose_set, known] : by_pose_set) {
      SCOPED_TRACE(trainer + " " + pose_set);
      const json& entry = summary["metrics"]["splat@" + trainer][pose_set];
      EXPECT_EQ(entry["trainer"], trainer);
      const bool fails = (trainer == "gsplat" && pose_set == "refined") ||
                         (trainer == "nerfstudio" && pose_set == "ground_truth");
      if (fails) {
        EXPECT_EQ(entry["status"], "failed");
        EXPECT_TRUE(entry["psnr"].is_null());
        EXPECT_TRUE(entry["raytime_psnr"].is_null());
        continue;
      }
      EXPECT_EQ(entry["status"], "ok");
      EXPECT_EQ(entry["psnr"].get<double>(), known.psnr);
      EXPECT_EQ(entry["ssim"].get<double>(), known.ssim);
      EXPECT_EQ(entry["lpips"].get<double>(), known.lpips);
      EXPECT_EQ(entry["exit_code"], 0);
      EXPECT_EQ(entry["reused"], false);
      // raytime's own scores of the same renders in each trainer's layout agree.
      EXPECT_NEAR(entry["raytime_psnr"].get<double>(), kRaytimePsnr, 1e-9);
      EXPECT_NEAR(entry["raytime_ssim"].get<double>(), kRaytimeSsim, 1e-9);
      EXPECT_EQ(entry["raytime_images"], trainer == "inria" ? 1 : trainer == "gsplat" ? 2 : 1);
    }
  }
  EXPECT_EQ(summary["metrics"]["splat@gsplat"]["refined"]["exit_code"], 3);
  EXPECT_EQ(summary["metrics"]["splat@gsplat"]["refined"]["error"],
            "the command exited with status 3");
  EXPECT_EQ(summary["metrics"]["splat@nerfstudio"]["ground_truth"]["exit_code"], 0);
  // One warning per failed pose set, naming the stage, the pose set and the log.
  std::vector<std::string> failed;
  for (const json& warning : summary["warnings"]) {
    ASSERT_EQ(warning["code"], "splat_failed") << warning.dump();
    failed.push_back(warning["stage"].get<std::string>() + " " +
                     warning["details"]["pose_set"].get<std::string>());
  }
  EXPECT_EQ(failed,
            (std::vector<std::string>{"splat@gsplat refined", "splat@nerfstudio ground_truth"}));
  EXPECT_NE(ReadFile(work_ / "splat@gsplat/refined.log").find("CUDA out of memory"),
            std::string::npos);
  EXPECT_NE(run.output.find("gsplat failed on pose set 'refined'"), std::string::npos);
  // The stage's own summary has each run with its command as run.
  for (const json& stage : summary["stages"]) {
    if (stage["id"] != "splat@inria") continue;
    EXPECT_EQ(stage["summary"]["num_ok"], 3);
    const std::string command = stage["summary"]["pose_sets"][0]["command"];
    EXPECT_NE(command.find(" prior " + (work_ / "splat@inria/prior").string() + " " +
                           (work_ / "3dgs/prior").string() + " "),
              std::string::npos)
        << command;
  }
  EXPECT_EQ(CountLines(ReadFile(fixture_ / "calls.log"), "gsplat refined"), 1);

  // Unchanged rerun: the complete stage is skipped, the others retry only their failed pose
  // set and read the successful ones again.
  const CommandResult again = Run();
  ASSERT_EQ(again.exit_code, 0) << again.output;
  const json second = ReadJson(work_ / "summary.json");
  std::map<std::string, std::string> status;
  for (const json& stage : second["stages"]) status[stage["id"]] = stage["status"];
  EXPECT_EQ(status["splat@inria"], "skipped");
  EXPECT_EQ(status["splat@gsplat"], "ran");
  EXPECT_EQ(status["splat@nerfstudio"], "ran");
  const std::string calls = ReadFile(fixture_ / "calls.log");
  EXPECT_EQ(CountLines(calls, "gsplat refined"), 2) << calls;
  EXPECT_EQ(CountLines(calls, "gsplat prior"), 1) << calls;
  EXPECT_EQ(CountLines(calls, "inria prior"), 1) << calls;
  EXPECT_EQ(second["metrics"]["splat@gsplat"]["prior"]["reused"], true);
  EXPECT_EQ(second["metrics"]["splat@gsplat"]["prior"]["psnr"].get<double>(), 20.5);
  EXPECT_EQ(second["metrics"]["splat@inria"]["prior"]["psnr"].get<double>(), 20.25);
  EXPECT_EQ(second["warnings"].size(), 2u);

  // The trainers fixed: only the two failed pose sets train again, and the run is ok.
  fs::remove(fixture_ / "fail_gsplat_refined");
  fs::remove(fixture_ / "nometrics_nerfstudio_ground_truth");
  const CommandResult fixed = Run();
  ASSERT_EQ(fixed.exit_code, 0) << fixed.output;
  const json third = ReadJson(work_ / "summary.json");
  EXPECT_EQ(third["status"], "ok");
  EXPECT_EQ(third["metrics"]["splat@gsplat"]["refined"]["psnr"].get<double>(), 22.25);
  EXPECT_EQ(third["metrics"]["splat@nerfstudio"]["ground_truth"]["lpips"].get<double>(), 0.125);
  const std::string all_calls = ReadFile(fixture_ / "calls.log");
  EXPECT_EQ(CountLines(all_calls, "gsplat prior"), 1) << all_calls;
  EXPECT_EQ(CountLines(all_calls, "gsplat refined"), 3) << all_calls;
  EXPECT_EQ(CountLines(all_calls, "nerfstudio ground_truth"), 3) << all_calls;
}

TEST_F(SplatStageTest, AMissingExportStopsBeforeAnyTrainerRuns) {
  std::ofstream(pipeline_) << "name: splat-missing\n"
                              "dataset: {format: strecha, root: data/sample/fountain-P11}\n"
                              "stages:\n"
                              "  - splat: {trainer: inria, poses: [prior, classical], command: \""
                           << StandIn("inria", fixture_) << "\"}\n";
  const CommandResult run = Run();
  EXPECT_EQ(run.exit_code, 2) << run.output;
  EXPECT_NE(run.output.find((work_ / "3dgs/classical").string()), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("formats: [3dgs]"), std::string::npos) << run.output;
  EXPECT_FALSE(fs::exists(fixture_ / "calls.log")) << "no trainer may start";
}

// A sweep over the trainer kinds, then its campaign report: Table 4 per trainer, with the known
// numbers and the failed training counted.
TEST_F(SplatStageTest, TheCampaignReportShowsTable4PerTrainer) {
  const fs::path sweep = dir_.path() / "sweep";
  // A placeholder the hook does not know is refused before anything runs.
  std::ofstream(pipeline_) << "name: splat-sweep\n"
                              "dataset: {format: strecha, root: data/sample/fountain-P11}\n"
                              "stages:\n"
                              "  - splat: {command: \"train {trainer} {data_dir}\"}\n";
  const CommandResult refused = Run();
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("unknown placeholder {trainer}"), std::string::npos)
      << refused.output;

  // The stand-in writes every trainer's format, so one command serves the swept trainer kinds.
  std::ofstream(pipeline_) << "name: splat-sweep\n"
                              "dataset: {format: strecha, root: data/sample/fountain-P11}\n"
                              "stages:\n"
                              "  - prior: {source: perturb, level_deg: 4, seed: 0}\n"
                              "  - splat: {poses: [prior, refined, ground_truth], command: \""
                           << StandIn("any", fixture_) << "\"}\n"
                           << "sweep:\n  splat.trainer: [gsplat, inria, nerfstudio]\n";
  std::ofstream(fixture_ / "fail_any_refined") << "";
  for (const std::string trainer : {"gsplat", "inria", "nerfstudio"}) {
    for (const auto& pose_set : kPoseSets) {
      WriteExportFixture(sweep / "runs" / ("trainer=" + trainer) / "3dgs" / pose_set);
    }
  }
  const CommandResult run =
      RunRaytime("run " + pipeline_.string() + " --workdir " + sweep.string() + " --jobs 1");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const std::string report = ReadFile(sweep / "report.md");
  ASSERT_NE(report.find("## Downstream 3DGS on held-out views (Table 4 shape)"), std::string::npos)
      << report;
  char own[64];
  std::snprintf(own, sizeof(own), "%.2f | %.3f", kRaytimePsnr, kRaytimeSsim);
  for (const auto& [trainer, by_pose_set] : kKnown) {
    SCOPED_TRACE(trainer);
    const size_t section = report.find("### `splat` (" + trainer + ")");
    ASSERT_NE(section, std::string::npos) << report;
    for (const auto& [pose_set, known] : by_pose_set) {
      // Then the seed spread ("–": one seed) and the time per model (the stand-in's, varies).
      char row[160];
      if (pose_set == "refined") {
        std::snprintf(row, sizeof(row), "| refined | – | – | – | – | – | – | – | 0/1 | 1 |");
      } else {
        std::snprintf(row, sizeof(row), "| %s | %.2f | %.3f | %.3f | %s | – | ", pose_set.c_str(),
                      known.psnr, known.ssim, known.lpips, own);
      }
      const size_t at = report.find(row, section);
      ASSERT_NE(at, std::string::npos) << row << "\n" << report;
      const std::string line = report.substr(at, report.find('\n', at) - at);
      const std::string end = pose_set == "refined" ? "| 0/1 | 1 |" : "| 1/1 | 0 |";
      EXPECT_EQ(line.substr(line.size() - end.size()), end) << line;
    }
    // Rows in report order: prior, refined, ground truth.
    EXPECT_LT(report.find("| prior |", section), report.find("| refined |", section));
    EXPECT_LT(report.find("| refined |", section), report.find("| ground_truth |", section));
  }
  const std::string csv = ReadFile(sweep / "report_splat.csv");
  EXPECT_NE(csv.find("splat,inria,0,(all),prior,1,1,1,0,20.25,0.5,0.5,"), std::string::npos) << csv;
  EXPECT_NE(ReadFile(sweep / "sweep.csv").find("metrics.splat.prior.psnr"), std::string::npos);
}

}  // namespace
}  // namespace raytime

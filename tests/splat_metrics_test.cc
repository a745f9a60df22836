// The trainers' metrics files (splat/splat_metrics.h) read from fixtures in the formats the
// trainers write (tests/data/splat: gsplat's stats/val_step<N>.json, Inria's results.json,
// nerfstudio's ns-eval output), the step each belongs to, malformed files, and where each trainer
// leaves its held-out renders.
#include "splat/splat_metrics.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "tests/input_error_of.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

const fs::path kFixtures = fs::path(RAYTIME_SOURCE_DIR) / "tests" / "data" / "splat";

void WriteText(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

TEST(SplatMetrics, GsplatTakesTheLastEvalStepByNumber) {
  // val_step6999.json sorts after val_step29999.json by name; the last step is 29999.
  const TrainerMetrics metrics = ReadGsplatStats((kFixtures / "gsplat").string());
  EXPECT_EQ(metrics.step, 29999);
  EXPECT_EQ(fs::path(metrics.file).filename(), "val_step29999.json");
  EXPECT_DOUBLE_EQ(metrics.psnr, 26.40625);
  EXPECT_DOUBLE_EQ(metrics.ssim, 0.85546875);
  EXPECT_DOUBLE_EQ(metrics.lpips, 0.1640625);
  EXPECT_EQ(metrics.num_gaussians, 1048576);
  EXPECT_DOUBLE_EQ(ReadTrainerMetrics("gsplat", (kFixtures / "gsplat").string()).psnr, 26.40625);
}

TEST(SplatMetrics, InriaTakesTheHighestIteration) {
  const TrainerMetrics metrics = ReadInriaResults((kFixtures / "inria").string());
  EXPECT_EQ(metrics.step, 30000);
  EXPECT_DOUBLE_EQ(metrics.psnr, 25.75);
  EXPECT_DOUBLE_EQ(metrics.ssim, 0.8359375);
  EXPECT_DOUBLE_EQ(metrics.lpips, 0.1953125);
  EXPECT_EQ(metrics.num_gaussians, -1);
  EXPECT_DOUBLE_EQ(ReadTrainerMetrics("inria", (kFixtures / "inria").string()).ssim, 0.8359375);
}

TEST(SplatMetrics, NerfstudioReadsResultsAndTheCheckpointStep) {
  const TrainerMetrics metrics = ReadNerfstudioEval((kFixtures / "nerfstudio/eval.json").string());
  EXPECT_EQ(metrics.step, 29999);
  EXPECT_DOUBLE_EQ(metrics.psnr, 25.25);
  EXPECT_DOUBLE_EQ(metrics.ssim, 0.8203125);
  EXPECT_DOUBLE_EQ(metrics.lpips, 0.2109375);
  // The hook's layout: RESULT/eval.json.
  EXPECT_DOUBLE_EQ(ReadTrainerMetrics("nerfstudio", (kFixtures / "nerfstudio").string()).lpips,
                   0.2109375);
}

TEST(SplatMetrics, LpipsIsOptionalPsnrAndSsimAreNot) {
  TempDir dir("splat_metrics");
  WriteText(dir.path() / "a/stats/val_step99.json", R"({"psnr": 20.5, "ssim": 0.5})");
  const TrainerMetrics metrics = ReadGsplatStats(dir / "a");
  EXPECT_DOUBLE_EQ(metrics.psnr, 20.5);
  EXPECT_TRUE(std::isnan(metrics.lpips));
  EXPECT_EQ(metrics.num_gaussians, -1);

  WriteText(dir.path() / "b/stats/val_step99.json", R"({"ssim": 0.5, "lpips": 0.1})");
  EXPECT_NE(InputErrorOf([&] { ReadGsplatStats(dir / "b"); }).find("has no 'psnr'"),
            std::string::npos);
  WriteText(dir.path() / "c/results.json", R"({"ours_7000": {"PSNR": 20, "SSIM": 1.5}})");
  const std::string out_of_range = InputErrorOf([&] { ReadInriaResults(dir / "c"); });
  EXPECT_NE(out_of_range.find("'ours_7000' 'SSIM' = 1.5 is outside [-1"), std::string::npos)
      << out_of_range;
  WriteText(dir.path() / "d/eval.json", R"({"results": {"psnr": "25", "ssim": 0.8}})");
  EXPECT_NE(InputErrorOf([&] {
              ReadTrainerMetrics("nerfstudio", dir / "d");
            }).find("'psnr' is not a number"),
            std::string::npos);
}

TEST(SplatMetrics, MissingAndMalformedFilesNameTheFile) {
  TempDir dir("splat_metrics");
  EXPECT_NE(InputErrorOf([&] { ReadGsplatStats(dir / "none"); }).find("no stats folder"),
            std::string::npos);
  fs::create_directories(dir.path() / "empty/stats");
  WriteText(dir.path() / "empty/stats/train_step99_rank0.json", "{}");
  EXPECT_NE(InputErrorOf([&] { ReadGsplatStats(dir / "empty"); }).find("no val_step<N>.json"),
            std::string::npos);
  EXPECT_NE(InputErrorOf([&] { ReadInriaResults(dir / "none"); }).find("results.json"),
            std::string::npos);

  // Python writes NaN for a diverged training; that is not JSON, and the message says why.
  WriteText(dir.path() / "nan/stats/val_step6999.json", R"({"psnr": NaN, "ssim": NaN})");
  const std::string nan = InputErrorOf([&] { ReadGsplatStats(dir / "nan"); });
  EXPECT_NE(nan.find("val_step6999.json"), std::string::npos) << nan;
  EXPECT_NE(nan.find("NaN or Infinity"), std::string::npos) << nan;
  WriteText(dir.path() / "cut/results.json", R"({"ours_30000": {"PSNR": 2)");
  EXPECT_NE(InputErrorOf([&] { ReadInriaResults(dir / "cut"); }).find("not valid JSON"),
            std::string::npos);
  WriteText(dir.path() / "other/results.json", R"({"baseline": {"PSNR": 20, "SSIM": 0.5}})");
  EXPECT_NE(InputErrorOf([&] { ReadInriaResults(dir / "other"); }).find("no entry 'ours_"),
            std::string::npos);
  WriteText(dir.path() / "list/eval.json", "[1, 2]");
  EXPECT_NE(InputErrorOf([&] {
              ReadNerfstudioEval(dir / "list/eval.json");
            }).find("expected a JSON object"),
            std::string::npos);
  WriteText(dir.path() / "noresults/eval.json", R"({"psnr": 25})");
  EXPECT_NE(InputErrorOf([&] {
              ReadNerfstudioEval(dir / "noresults/eval.json");
            }).find("no 'results' object"),
            std::string::npos);
  EXPECT_THROW(ReadTrainerMetrics("splatter", dir / "none"), InputError);
}

void WritePng(const fs::path& path, int width) {
  fs::create_directories(path.parent_path());
  ASSERT_TRUE(cv::imwrite(path.string(), cv::Mat(4, width, CV_8UC3, cv::Scalar(9, 9, 9))));
}

TEST(SplatMetrics, HeldOutRendersOfEachTrainer) {
  TempDir dir("splat_metrics");
  TrainerMetrics metrics;
  std::string reason;

  // gsplat: only the renders of the step the stats came from, in index order.
  metrics.step = 29999;
  WritePng(dir.path() / "g/renders/val_step6999_0000.png", 8);
  WritePng(dir.path() / "g/renders/val_step29999_0001.png", 8);
  WritePng(dir.path() / "g/renders/val_step29999_0000.png", 8);
  std::vector<HeldOutView> views = TrainerHeldOutViews("gsplat", dir / "g", metrics, &reason);
  ASSERT_EQ(views.size(), 2u);
  EXPECT_EQ(fs::path(views[0].render_path).filename(), "val_step29999_0000.png");
  EXPECT_EQ(views[0].reference_path, "");  // side by side
  metrics.step = 99;
  EXPECT_TRUE(TrainerHeldOutViews("gsplat", dir / "g", metrics, &reason).empty());
  EXPECT_NE(reason.find("val_step99_*.png"), std::string::npos) << reason;

  // Inria: test/ours_<iteration>/{renders,gt}.
  metrics.step = 30000;
  WritePng(dir.path() / "i/test/ours_30000/renders/00000.png", 4);
  WritePng(dir.path() / "i/test/ours_30000/gt/00000.png", 4);
  views = TrainerHeldOutViews("inria", dir / "i", metrics, &reason);
  ASSERT_EQ(views.size(), 1u);
  EXPECT_EQ(fs::path(views[0].reference_path).parent_path().filename(), "gt");
  metrics.step = 7000;
  EXPECT_TRUE(TrainerHeldOutViews("inria", dir / "i", metrics, &reason).empty());
  EXPECT_NE(reason.find("ours_7000"), std::string::npos) << reason;

  // nerfstudio: ns-eval --render-output-path RESULT/eval_renders.
  WritePng(dir.path() / "n/eval_renders/eval_img_0000.png", 8);
  views = TrainerHeldOutViews("nerfstudio", dir / "n", metrics, &reason);
  ASSERT_EQ(views.size(), 1u);
  EXPECT_TRUE(TrainerHeldOutViews("nerfstudio", dir / "g", metrics, &reason).empty());
  EXPECT_NE(reason.find("--render-output-path"), std::string::npos) << reason;
}

}  // namespace
}  // namespace raytime

// The trainer hook (splat/splat_trainer.h) on stand-in shell commands: the default command
// lines, placeholders and quoting, a run that writes a trainer's output format, a non-zero exit, a
// success without metrics, a timeout that stops what the command started, a missing working
// directory, and reading an earlier result without running again.
#include "splat/splat_trainer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "core/atomic_file.h"
#include "core/error.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// The problems ValidateOptions reports for `options` ("" when valid).
std::string Problems(const SplatTrainerOptions& options) {
  try {
    ValidateOptions(options, "stage 'splat'");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(SplatTrainer, DefaultCommandsAreTheTrainersUsualOnes) {
  EXPECT_EQ(DefaultSplatCommand("gsplat"),
            "python examples/simple_trainer.py default --data_dir {data_dir} --result_dir "
            "{result_dir} --data_factor 1 --disable_viewer");
  EXPECT_EQ(DefaultSplatCommand("inria"),
            "python train.py -s {data_dir} -m {result_dir} --eval && python render.py -m "
            "{result_dir} && python metrics.py -m {result_dir}");
  EXPECT_EQ(DefaultSplatCommand("nerfstudio"),
            "ns-train splatfacto --data {data_dir} --output-dir {result_dir} --experiment-name "
            "raytime --timestamp run --vis tensorboard && ns-eval --load-config "
            "{result_dir}/raytime/splatfacto/run/config.yml --output-path {result_dir}/eval.json "
            "--render-output-path {result_dir}/eval_renders");
  EXPECT_THROW(DefaultSplatCommand("splatter"), InputError);
}

TEST(SplatTrainer, PlaceholdersAreReplacedAbsoluteAndQuoted) {
  SplatTrainerOptions options;
  options.trainer = "inria";
  SplatJob job{"refined@gnc", "/w/3dgs/refined@gnc", "/w/splat/refined@gnc", "", false};
  EXPECT_EQ(ExpandSplatCommand(options, job),
            "python train.py -s /w/3dgs/refined@gnc -m /w/splat/refined@gnc --eval && python "
            "render.py -m /w/splat/refined@gnc && python metrics.py -m /w/splat/refined@gnc");
  options.command = "run {pose_set} '{data_dir}x' ${HOME} {1..3} {a,b} {result_dir}/x";
  job.result_dir = "/w/it's here";
  EXPECT_EQ(ExpandSplatCommand(options, job),
            "run refined@gnc '/w/3dgs/refined@gncx' ${HOME} {1..3} {a,b} '/w/it'\\''s here'/x");
  job.data_dir = "relative/3dgs";
  options.command = "{data_dir}";
  EXPECT_EQ(ExpandSplatCommand(options, job), (fs::current_path() / "relative/3dgs").string());

  EXPECT_EQ(Problems(options), "");
  options.command = "train {data-dir} {datadir} ${datadir}";
  const std::string problems = Problems(options);
  EXPECT_NE(problems.find("unknown placeholder {data-dir}"), std::string::npos) << problems;
  EXPECT_NE(problems.find("unknown placeholder {datadir}"), std::string::npos) << problems;
  options.command = "";
  options.trainer = "splatter";
  EXPECT_NE(Problems(options).find("option 'trainer'"), std::string::npos);
  options.trainer = "gsplat";
  options.timeout_s = -1;
  EXPECT_NE(Problems(options).find("option 'timeout_s'"), std::string::npos);
}

// A job in a fresh directory; the stand-in commands below write the trainers' real formats.
struct Fixture {
  TempDir dir{"splat_trainer"};
  SplatJob Job(const std::string& pose_set) const {
    return {pose_set, dir / ("3dgs/" + pose_set), dir / ("splat/" + pose_set),
            dir / ("splat/" + pose_set + ".log"), false};
  }
};

TEST(SplatTrainer, ARunThatWritesInriasFormatIsReadAndScored) {
  Fixture fixture;
  SplatJob job = fixture.Job("refined");
  fs::create_directories(job.data_dir);
  // A result folder from an earlier run: emptied before the trainer runs.
  fs::create_directories(job.result_dir);
  std::ofstream(job.result_dir + "/stale.txt") << "old";
  // A render 8 grey levels off its ground truth everywhere: raytime's PSNR = 20 log10(255 / 8).
  const std::string images = fixture.dir / "images";
  fs::create_directories(images);
  ASSERT_TRUE(cv::imwrite(images + "/gt.png", cv::Mat(16, 16, CV_8UC3, cv::Scalar(100, 100, 100))));
  ASSERT_TRUE(
      cv::imwrite(images + "/render.png", cv::Mat(16, 16, CV_8UC3, cv::Scalar(108, 108, 108))));
  SplatTrainerOptions options;
  options.trainer = "inria";
  options.command =
      "echo training {pose_set}; test -d {data_dir} && mkdir -p {result_dir}/test/ours_30000/gt "
      "{result_dir}/test/ours_30000/renders && cp " +
      images + "/gt.png {result_dir}/test/ours_30000/gt/00000.png && cp " + images +
      "/render.png {result_dir}/test/ours_30000/renders/00000.png && printf '%s' "
      "'{\"ours_30000\": {\"SSIM\": 0.5, \"PSNR\": 21.5, \"LPIPS\": 0.25}}' > "
      "{result_dir}/results.json";
  const SplatRunSummary summary = RunSplatTrainer(options, job);
  EXPECT_EQ(summary.status, "ok") << summary.error << "\n" << ReadTextFile(job.log_path);
  EXPECT_EQ(summary.error, "");
  EXPECT_EQ(summary.exit_code, 0);
  EXPECT_FALSE(summary.reused);
  EXPECT_FALSE(fs::exists(job.result_dir + "/stale.txt"));
  EXPECT_EQ(summary.step, 30000);
  EXPECT_DOUBLE_EQ(summary.psnr, 21.5);
  EXPECT_DOUBLE_EQ(summary.ssim, 0.5);
  EXPECT_DOUBLE_EQ(summary.lpips, 0.25);
  EXPECT_EQ(summary.raytime_images, 1);
  EXPECT_NEAR(summary.raytime_psnr, 20.0 * std::log10(255.0 / 8.0), 1e-9);
  EXPECT_GT(summary.raytime_ssim, 0.0);
  EXPECT_LT(summary.raytime_ssim, 1.0);
  EXPECT_EQ(summary.log_tail, "");
  const std::string log = ReadTextFile(job.log_path);
  EXPECT_EQ(log.rfind("$ echo training refined;", 0), 0u) << log;
  EXPECT_NE(log.find("training refined\n"), std::string::npos) << log;
  // The summary's JSON: NaN-free here, keys are the field names.
  const nlohmann::json json = summary;
  EXPECT_EQ(json["raytime_images"], 1);
  EXPECT_EQ(json["status"], "ok");

  // Reading the result again without running (the command would fail now).
  options.command = "exit 1";
  job.reuse_result = true;
  const SplatRunSummary reused = RunSplatTrainer(options, job);
  EXPECT_EQ(reused.status, "ok") << reused.error;
  EXPECT_TRUE(reused.reused);
  EXPECT_DOUBLE_EQ(reused.psnr, 21.5);
  EXPECT_EQ(reused.exit_code, -1);
}

TEST(SplatTrainer, AFailedCommandIsAFailureWithTheLogsLastLines) {
  Fixture fixture;
  const SplatJob job = fixture.Job("prior");
  SplatTrainerOptions options;
  options.trainer = "gsplat";
  options.command =
      "mkdir -p {result_dir}/stats && echo '{\"psnr\": 30, \"ssim\": 0.9}' > "
      "{result_dir}/stats/val_step6999.json; for i in 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 "
      "18 19 20 21 22; do echo line $i; done; echo 'CUDA out of memory' >&2; exit 3";
  const SplatRunSummary summary = RunSplatTrainer(options, job);
  EXPECT_EQ(summary.status, "failed");
  EXPECT_EQ(summary.exit_code, 3);
  EXPECT_EQ(summary.error, "the command exited with status 3");
  // Metrics the failed command left behind are not reported.
  EXPECT_TRUE(std::isnan(summary.psnr));
  EXPECT_NE(summary.log_tail.find("CUDA out of memory"), std::string::npos) << summary.log_tail;
  EXPECT_EQ(summary.log_tail.find("line 3\n"), std::string::npos) << "20 lines only";
  EXPECT_NE(summary.log_tail.find("line 4\n"), std::string::npos) << summary.log_tail;
}

TEST(SplatTrainer, SuccessWithoutMetricsIsAFailure) {
  Fixture fixture;
  const SplatJob job = fixture.Job("ground_truth");
  SplatTrainerOptions options;
  options.trainer = "nerfstudio";
  options.command = "echo done";
  const SplatRunSummary summary = RunSplatTrainer(options, job);
  EXPECT_EQ(summary.status, "failed");
  EXPECT_EQ(summary.exit_code, 0);
  EXPECT_NE(summary.error.find("metrics do not read"), std::string::npos) << summary.error;
  EXPECT_NE(summary.error.find("eval.json"), std::string::npos) << summary.error;
  EXPECT_NE(summary.log_tail.find("done"), std::string::npos);
}

TEST(SplatTrainer, ATimeoutStopsTheCommandAndWhatItStarted) {
  Fixture fixture;
  const SplatJob job = fixture.Job("prior");
  const std::string pid_file = fixture.dir / "sleep.pid";
  SplatTrainerOptions options;
  options.command = "sleep 60 & echo $! > " + pid_file + "; wait";
  options.timeout_s = 0.3;
  const SplatRunSummary summary = RunSplatTrainer(options, job);
  EXPECT_EQ(summary.status, "failed");
  EXPECT_TRUE(summary.timed_out);
  EXPECT_NE(summary.error.find("timed out"), std::string::npos) << summary.error;
  EXPECT_LT(summary.seconds, 10.0);
  ASSERT_TRUE(fs::exists(pid_file));
  const std::string pid = ReadTextFile(pid_file).substr(0, ReadTextFile(pid_file).find('\n'));
  // Gone, or a zombie waiting for its reaper: either way no longer running.
  bool running = true;
  for (int i = 0; i < 200 && running; ++i) {
    std::ifstream stat("/proc/" + pid + "/stat");
    std::string id, name, state;
    running = static_cast<bool>(stat >> id >> name >> state) && state != "Z";
    if (running) ::usleep(10000);
  }
  EXPECT_FALSE(running) << "the command's sleep outlived the timeout";
}

TEST(SplatTrainer, WorkingDirectory) {
  Fixture fixture;
  const SplatJob job = fixture.Job("prior");
  SplatTrainerOptions options;
  options.working_dir = fixture.dir / "missing";
  EXPECT_THROW(RunSplatTrainer(options, job), InputError);
  fs::create_directories(fixture.dir / "checkout");
  options.working_dir = fixture.dir / "checkout";
  options.command = "pwd > {result_dir}/pwd.txt";
  const SplatRunSummary summary = RunSplatTrainer(options, job);
  EXPECT_EQ(summary.status, "failed");  // no metrics, but it ran where it was told
  EXPECT_EQ(ReadTextFile(job.result_dir + "/pwd.txt"),
            fs::canonical(fixture.dir / "checkout").string() + "\n");
}

}  // namespace
}  // namespace raytime

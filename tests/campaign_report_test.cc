// Tests of campaign reports (SPEC §6; paper §4.8 "Basin of convergence", §4.9): Wilson intervals
// against reference values, and the aggregation of hand-made sweep rows with known counts,
// medians, halving counts and failed runs.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "core/error.h"
#include "report/campaign_report.h"
#include "report/html.h"
#include "report/sweep_row.h"
#include "tests/temp_dir.h"

namespace raytime {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A sweep row's records (core/json_fields.h): a number that is not finite is written as null and
// read back as NaN, and so is one a summary does not have (an older run's): "not reported", never
// 0; other fields absent or of another type take their default.
TEST(SweepRowTest, ANumberNotReportedReadsBackAsNaNAndNotAsZero) {
  PoseErrorStatistics statistics;
  statistics.num_frames = 11;
  statistics.mean_rotation_deg = 0.25;
  statistics.alignment_rotation_sigma_deg = std::numeric_limits<double>::infinity();
  statistics.success = true;
  const nlohmann::json written = statistics;
  EXPECT_TRUE(written.at("alignment_rotation_sigma_deg").is_null());
  const PoseErrorStatistics read = written.get<PoseErrorStatistics>();
  EXPECT_EQ(read.num_frames, 11);
  EXPECT_EQ(read.mean_rotation_deg, 0.25);
  EXPECT_TRUE(std::isnan(read.alignment_rotation_sigma_deg));
  EXPECT_TRUE(read.success);

  const PoseErrorStatistics older = nlohmann::json{
      {"num_frames", 3},
      {"mean_rotation_deg", 1.5},
      {"success", "yes"}}.get<PoseErrorStatistics>();
  EXPECT_EQ(older.num_frames, 3);
  EXPECT_EQ(older.mean_rotation_deg, 1.5);
  EXPECT_TRUE(std::isnan(older.median_rotation_deg));
  EXPECT_TRUE(std::isnan(older.mean_relative_rotation_deg));
  EXPECT_EQ(older.num_relative_pairs, 0);
  EXPECT_FALSE(older.success);  // not a boolean

  SweepSplatResult splat;
  splat.trainer = "gsplat";
  splat.status = "ok";
  splat.psnr = 24.5;
  const SweepSplatResult back = SweepSplatResult::FromJson(splat.ToJson());
  EXPECT_EQ(back.trainer, "gsplat");
  EXPECT_TRUE(back.ok());
  EXPECT_EQ(back.psnr, 24.5);
  EXPECT_TRUE(std::isnan(back.lpips));
  EXPECT_TRUE(splat.ToJson().at("lpips").is_null());
  EXPECT_EQ(SweepSplatResult::FromJson({{"trainer", 7}}).trainer, "");
}

TEST(WilsonIntervalTest, MatchesReferenceValues) {
  // Reference values: roots of (k/n - p)^2 = z^2 p (1 - p) / n found by bisection, z = 1.959964.
  struct Case {
    int successes, trials;
    double lower, upper;
  };
  for (const Case& c :
       {Case{8, 10, 0.4902, 0.9433}, Case{0, 10, 0.0, 0.2775}, Case{10, 10, 0.7225, 1.0},
        Case{3, 3, 0.4385, 1.0}, Case{1, 2, 0.0945, 0.9055}, Case{72, 90, 0.7059, 0.8696}}) {
    const ProportionInterval interval = WilsonInterval(c.successes, c.trials);
    EXPECT_NEAR(interval.lower, c.lower, 5e-5) << c.successes << "/" << c.trials;
    EXPECT_NEAR(interval.upper, c.upper, 5e-5) << c.successes << "/" << c.trials;
  }
}

TEST(WilsonIntervalTest, ReproducesThePapersIntervals) {
  // Paper §4.8: 85/85 per level [0.96, 1.00]; 17/17 scenes [0.82, 1.00]; 144/170 [0.79, 0.89].
  EXPECT_NEAR(WilsonInterval(85, 85).lower, 0.96, 0.005);
  EXPECT_NEAR(WilsonInterval(17, 17).lower, 0.82, 0.005);
  EXPECT_NEAR(WilsonInterval(144, 170).lower, 0.79, 0.005);
  EXPECT_NEAR(WilsonInterval(144, 170).upper, 0.89, 0.005);
}

TEST(WilsonIntervalTest, BoundsAreExactAtTheEnds) {
  EXPECT_EQ(WilsonInterval(0, 0).lower, 0.0);
  EXPECT_EQ(WilsonInterval(0, 0).upper, 1.0);
  EXPECT_EQ(WilsonInterval(0, 7).lower, 0.0);
  EXPECT_EQ(WilsonInterval(7, 7).upper, 1.0);
  // A wider z widens the interval.
  EXPECT_LT(WilsonInterval(5, 10, 2.575829).lower, WilsonInterval(5, 10).lower);
}

// Errors one arm reports in one run: Sim(3) and absolute-frame mean rotation, degrees.
struct ArmErrors {
  double sim3_deg;
  double none_deg;
};

// The stage that writes an arm's pose set, by the pipelines' naming: refined@X <- refine@X.
std::string WriterOf(const std::string& arm) {
  const size_t at = arm.find('@');
  const std::string base = arm.substr(0, at);
  return (base == "refined" ? std::string("refine") : base) +
         (at == std::string::npos ? "" : arm.substr(at));
}

// A sweep row as `raytime run` writes it: swept values as strings, errors per arm and alignment.
SweepRow Row(const std::string& scene, const std::string& level, const std::string& seed,
             const std::map<std::string, ArmErrors>& arms,
             const std::map<std::string, double>& seconds = {}) {
  SweepRow row;
  row.run = "root=" + scene + ",level_deg=" + level + ",seed=" + seed;
  row.swept = {
      {"dataset.root", "data/strecha/" + scene}, {"prior.level_deg", level}, {"prior.seed", seed}};
  row.status = "ok";
  row.seconds = 1.0;
  // What a run that reported nothing reads as: every number NaN.
  const PoseErrorStatistics not_reported = nlohmann::json::object().get<PoseErrorStatistics>();
  for (const auto& [arm, errors] : arms) {
    PoseErrorStatistics& sim3 = row.errors[arm]["sim3"] = not_reported;
    sim3.mean_rotation_deg = sim3.median_rotation_deg = errors.sim3_deg;
    sim3.mean_centre_m = 0.01 * errors.sim3_deg;
    sim3.success = errors.sim3_deg < 1.0;
    // Only scene A has a scene scale (2 m): the relative error is absent elsewhere (NaN).
    if (scene == "A") sim3.mean_centre_relative = 0.01 * errors.sim3_deg / 2.0;
    sim3.mean_relative_rotation_deg = 0.5 * errors.sim3_deg;
    // Only scene B reports the alignment's own rotation (NaN in A: rows of older runs).
    if (scene == "B") sim3.alignment_rotation_sigma_deg = 0.1 * errors.sim3_deg;
    PoseErrorStatistics& none = row.errors[arm]["none"] = not_reported;
    none.mean_rotation_deg = errors.none_deg;
    none.mean_centre_m = 0.02 * errors.none_deg;
    row.pose_set_stage[arm] = WriterOf(arm);
  }
  row.stage_seconds = seconds;
  row.guardrails_fired["refine@gnc"] = {};
  return row;
}

// Two scenes x levels {0, 4} x seeds {0, 1}; scene B's run at 4°, seed 1 failed.
std::vector<SweepRow> HandMadeRows() {
  std::vector<SweepRow> rows = {
      Row("A", "0", "0",
          {{"prior", {0, 0}}, {"refined@gnc", {0.2, 0.3}}, {"classical", {0.15, 0.1}}}),
      Row("A", "0", "1",
          {{"prior", {0, 0}}, {"refined@gnc", {0.3, 0.5}}, {"classical", {0.25, 0.2}}}),
      Row("A", "4", "0",
          {{"prior", {3.9, 4.0}}, {"refined@gnc", {0.2, 1.5}}, {"classical", {3.8, 4.1}}},
          {{"prior", 0.1}, {"refine@gnc", 10.0}, {"classical", 3.0}}),
      Row("A", "4", "1",
          {{"prior", {4.1, 4.0}}, {"refined@gnc", {2.5, 1.9}}, {"classical", {3.0, 4.0}}},
          {{"prior", 0.1}, {"refine@gnc", 20.0}, {"classical", 5.0}}),
      Row("B", "4", "0",
          {{"prior", {3.5, 4.0}}, {"refined@gnc", {0.4, 1.0}}, {"classical", {3.6, 3.9}}},
          {{"prior", 0.1}, {"refine@gnc", 40.0}, {"classical", 7.0}}),
      Row("B", "0", "0",
          {{"prior", {0, 0}},
           {"refined@gnc", {0.25, 0.4}},
           {"refined", {0.3, 0.3}},
           {"refined@plain", {0.3, 0.3}},
           {"refined@anchored", {0.3, 0.3}},
           {"classical@tuned", {0.3, 0.3}},
           {"classical@mapper", {0.3, 9.0}},
           {"ground_truth", {0, 0}}},
          {{"refine", 30.0}, {"classical@mapper", 60.0}}),
      Row("B", "0", "1", {{"prior", {0, 0}}, {"refined@gnc", {0.22, 0.3}}}),
  };
  SweepRow failed;
  failed.run = "root=B,level_deg=4,seed=1";
  failed.swept = {
      {"dataset.root", "data/strecha/B"}, {"prior.level_deg", "4"}, {"prior.seed", "1"}};
  failed.status = "failed";
  failed.error = "refine@gnc: solver | diverged";
  failed.seconds = 2.0;
  rows.push_back(failed);
  return rows;
}

TEST(CampaignReportTest, CountsAndMediansPerCell) {
  const CampaignReport report = AggregateCampaign(HandMadeRows());
  EXPECT_EQ(report.total_runs, 8);
  EXPECT_EQ(report.scenes, (std::vector<std::string>{"A", "B"}));
  EXPECT_EQ(report.levels, (std::vector<double>{0.0, 4.0}));
  EXPECT_EQ(report.arms, (std::vector<std::string>{
                             "prior", "refined", "refined@plain", "refined@gnc", "refined@anchored",
                             "classical", "classical@tuned", "classical@mapper", "ground_truth"}));
  ASSERT_EQ(report.pooled_keys.size(), 1u);
  EXPECT_EQ(report.pooled_keys[0].first, "prior.seed");
  EXPECT_EQ(report.pooled_keys[0].second, 2);

  // 4°, over scenes: three scored runs (the fourth failed), 0.2° and 0.4° succeed.
  const CampaignCell* gnc = report.Find(CampaignReport::kAllScenes, 4.0, "refined@gnc");
  ASSERT_NE(gnc, nullptr);
  EXPECT_EQ(gnc->sim3.runs, 3);
  EXPECT_EQ(gnc->sim3.successes, 2);
  EXPECT_DOUBLE_EQ(gnc->sim3.median_rotation_deg, 0.4);
  EXPECT_DOUBLE_EQ(gnc->sim3.median_centre_m, 0.004);
  // Relative centre error only where a scene scale is known (scene A): median of 0.001, 0.0125.
  EXPECT_DOUBLE_EQ(gnc->sim3.median_centre_relative, 0.5 * (0.001 + 0.0125));
  // Relative rotations from all three runs (0.1, 1.25, 0.2); the fit's own rotation from B only.
  EXPECT_DOUBLE_EQ(gnc->sim3.median_relative_rotation_deg, 0.2);
  EXPECT_DOUBLE_EQ(gnc->sim3.median_alignment_rotation_sigma_deg, 0.1 * 0.4);
  // Halving under Sim(3): 0.2 <= 1.95 and 0.4 <= 1.75, not 2.5 <= 2.05; absolute: all three.
  EXPECT_EQ(gnc->sim3.halving_runs, 3);
  EXPECT_EQ(gnc->sim3.halves_baseline, 2);
  EXPECT_EQ(gnc->none.halving_runs, 3);
  EXPECT_EQ(gnc->none.halves_baseline, 3);
  EXPECT_EQ(gnc->none.successes, 0);
  EXPECT_DOUBLE_EQ(gnc->none.median_rotation_deg, 1.5);
  EXPECT_EQ(gnc->stage_id, "refine@gnc");
  EXPECT_DOUBLE_EQ(gnc->median_seconds, 20.0);
  // Scene-level reading: A has 1 of 2 runs, B 1 of 1, so one scene of two succeeds throughout.
  EXPECT_EQ(gnc->scene_success.scenes, 2);
  EXPECT_EQ(gnc->scene_success.scenes_all_succeed, 1);

  const CampaignCell* gnc_zero = report.Find(CampaignReport::kAllScenes, 0.0, "refined@gnc");
  ASSERT_NE(gnc_zero, nullptr);
  EXPECT_EQ(gnc_zero->sim3.runs, 4);
  EXPECT_EQ(gnc_zero->sim3.successes, 4);
  EXPECT_DOUBLE_EQ(gnc_zero->sim3.median_rotation_deg, 0.5 * (0.22 + 0.25));
  EXPECT_TRUE(std::isnan(gnc_zero->median_seconds));  // no seconds.refine@gnc column there
  EXPECT_EQ(gnc_zero->stage_id, "");
  EXPECT_EQ(gnc_zero->scene_success.scenes_all_succeed, 2);

  const CampaignCell* gnc_a = report.Find("A", 4.0, "refined@gnc");
  ASSERT_NE(gnc_a, nullptr);
  EXPECT_EQ(gnc_a->sim3.runs, 2);
  EXPECT_EQ(gnc_a->sim3.successes, 1);
  EXPECT_DOUBLE_EQ(gnc_a->sim3.median_rotation_deg, 0.5 * (0.2 + 2.5));

  // The baseline never "halves" itself; its level-0 errors are exactly 0 and succeed.
  const CampaignCell* prior = report.Find(CampaignReport::kAllScenes, 4.0, "prior");
  ASSERT_NE(prior, nullptr);
  EXPECT_EQ(prior->sim3.successes, 0);
  EXPECT_DOUBLE_EQ(prior->sim3.median_rotation_deg, 3.9);
  EXPECT_EQ(prior->sim3.halving_runs, 0);
  EXPECT_DOUBLE_EQ(prior->median_seconds, 0.1);
  EXPECT_EQ(report.Find(CampaignReport::kAllScenes, 0.0, "prior")->sim3.successes, 4);

  // The classical control is scored in the runs that have it (two at 0° in scene A only).
  const CampaignCell* classical = report.Find(CampaignReport::kAllScenes, 0.0, "classical");
  ASSERT_NE(classical, nullptr);
  EXPECT_EQ(classical->sim3.runs, 2);
  EXPECT_DOUBLE_EQ(classical->sim3.median_rotation_deg, 0.2);
  EXPECT_EQ(report.Find("B", 0.0, "classical"), nullptr);
  EXPECT_DOUBLE_EQ(report.Find(CampaignReport::kAllScenes, 4.0, "classical")->median_seconds, 5.0);
  EXPECT_EQ(report.Find(CampaignReport::kAllScenes, 0.0, "classical@mapper")->stage_id,
            "classical@mapper");
  EXPECT_EQ(report.Find(CampaignReport::kAllScenes, 0.0, "refined")->stage_id, "refine");
  // No stage wrote the ground truth in these rows: no stage, no time.
  const CampaignCell* ground_truth = report.Find(CampaignReport::kAllScenes, 0.0, "ground_truth");
  EXPECT_EQ(ground_truth->stage_id, "");
  EXPECT_TRUE(std::isnan(ground_truth->median_seconds));
}

TEST(CampaignReportTest, FailedRunsAreCountedAndListed) {
  const CampaignReport report = AggregateCampaign(HandMadeRows());
  ASSERT_EQ(report.failed_runs.size(), 1u);
  EXPECT_EQ(report.failed_runs[0].run, "root=B,level_deg=4,seed=1");
  EXPECT_EQ(report.failed_runs[0].scene, "B");
  EXPECT_EQ(report.failed_runs[0].level_deg, 4.0);
  EXPECT_EQ(report.FailedRunsAt(CampaignReport::kAllScenes, 4.0), 1);
  EXPECT_EQ(report.FailedRunsAt("B", 4.0), 1);
  EXPECT_EQ(report.FailedRunsAt("A", 4.0), 0);
  EXPECT_EQ(report.FailedRunsAt(CampaignReport::kAllScenes, 0.0), 0);

  const std::string markdown = CampaignReportMarkdown(report, "W/sweep.json");
  EXPECT_NE(markdown.find("8 runs (7 ok, 1 failed)"), std::string::npos) << markdown;
  EXPECT_NE(
      markdown.find("| 4° | 0/3 (3.90°) | – | – | 2/3 (0.40°) | – | 0/3 (3.60°) | – | – | – | 1 |"),
      std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("refine@gnc: solver \\| diverged"), std::string::npos) << markdown;
  // Table 6 shape: the best ray-time arm (most successes) beside the controls, with seconds.
  EXPECT_NE(markdown.find("| refined@gnc (best ray-time arm) | 4/4, "), std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find(", – | 2/3, 0.40°, 20.0 s |"), std::string::npos) << markdown;
  EXPECT_NE(markdown.find("### B"), std::string::npos);
  EXPECT_NE(markdown.find("## Accuracy beside the Sim(3) fit's resolution"), std::string::npos);
  EXPECT_NE(markdown.find("| refined@gnc | 0.235° ± 0.024 / rel. 0.117° | 0.400° ± 0.040 / rel. "
                          "0.200° |"),
            std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("| refined@gnc | 0/4 (abs. 0/4) | 2/3 (abs. 3/3) |"), std::string::npos)
      << markdown;

  const std::string csv = CampaignCellsCsv(report);
  size_t lines = 0;
  for (char c : csv) lines += c == '\n' ? 1 : 0;
  EXPECT_EQ(lines, report.cells.size() + 1);
  EXPECT_EQ(csv.rfind("scene,level_deg,arm,stage,failed_runs,sim3_runs,sim3_successes,", 0), 0u);
  EXPECT_NE(csv.find("\n(all),4,refined@gnc,refine@gnc,1,3,2,0.6666666667,"), std::string::npos)
      << csv;
}

TEST(CampaignReportTest, SuccessThresholdIsConfigurable) {
  CampaignReportOptions options;
  options.success_rotation_deg = 3.0;
  const CampaignReport report = AggregateCampaign(HandMadeRows(), options);
  EXPECT_EQ(report.Find(CampaignReport::kAllScenes, 4.0, "refined@gnc")->sim3.successes, 3);
  EXPECT_EQ(report.Find(CampaignReport::kAllScenes, 4.0, "classical")->sim3.successes, 0);
  EXPECT_NE(CampaignReportMarkdown(report, "x").find("below 3°"), std::string::npos);
}

TEST(CampaignReportTest, UnsweptLevelAndSceneFormOneCell) {
  SweepRow row = Row("A", "0", "0", {{"prior", {2.0, 2.0}}});
  row.swept = {{"prior.seed", "0"}};
  const CampaignReport report = AggregateCampaign({row});
  EXPECT_FALSE(report.level_swept);
  EXPECT_EQ(report.scenes, (std::vector<std::string>{"(not swept)"}));
  ASSERT_NE(report.Find(CampaignReport::kAllScenes, 0.0, "prior"), nullptr);
  EXPECT_NE(CampaignReportMarkdown(report, "x").find("| (not swept) | 0/1 (2.00°) |"),
            std::string::npos);
}

TEST(CampaignReportTest, BadLevelNamesTheRun) {
  std::vector<SweepRow> rows = HandMadeRows();
  rows[2].swept[1].second = "four";
  try {
    AggregateCampaign(rows);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("root=A,level_deg=4,seed=0"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("'four'"), std::string::npos) << e.what();
  }
}

class SweepFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("raytime_campaign_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& contents) {
    const fs::path path = dir_ / "sweep.json";
    std::ofstream(path) << contents;
    return path.string();
  }

  // The InputError message of reading `path`, or "" when it reads.
  static std::string ReadError(const std::string& path) {
    try {
      ReadSweepRows(path);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  }

  fs::path dir_;
};

TEST_F(SweepFileTest, ReadsRowsAndNamesTheFileOnBadInput) {
  json rows = json::array();
  for (const SweepRow& row : HandMadeRows()) rows.push_back(row.ToJson());
  const std::vector<SweepRow> read = ReadSweepRows(Write(rows.dump(2)));
  ASSERT_EQ(read.size(), 8u);
  // Every field survives the round trip (NaN as null and back).
  EXPECT_EQ(read[5].ToJson(), HandMadeRows()[5].ToJson());
  EXPECT_EQ(read[7].error, "refine@gnc: solver | diverged");

  const std::string missing = (dir_ / "nothing.json").string();
  EXPECT_NE(ReadError(missing).find(missing), std::string::npos);

  const std::string malformed = Write("[\n  {\"run\": 1},\n  {\"run\": \n]\n");
  const std::string message = ReadError(malformed);
  EXPECT_NE(message.find(malformed + ":4"), std::string::npos) << message;

  EXPECT_NE(ReadError(Write("{\"run\": 1}")).find("expected a JSON array"), std::string::npos);
  EXPECT_NE(ReadError(Write("[1]")).find("sweep row 1: not a sweep row"), std::string::npos);
}

// One pose set's training as a run's splat stage reports it.
SweepSplatResult Training(const std::string& trainer, double psnr, double ssim, double lpips,
                          double raytime_psnr = kNoValue) {
  SweepSplatResult result;
  result.trainer = trainer;
  result.status = "ok";
  result.psnr = psnr;
  result.ssim = ssim;
  result.lpips = lpips;
  result.raytime_psnr = raytime_psnr;
  result.raytime_ssim = std::isnan(raytime_psnr) ? kNoValue : 0.5;
  result.seconds = 100.0;
  return result;
}

SweepSplatResult FailedTraining(const std::string& trainer) {
  SweepSplatResult result;
  result.trainer = trainer;
  result.status = "failed";
  return result;
}

// Two scenes, two seeds, gsplat in stage splat and Inria in splat@inria: Table 4's cells are the
// mean over scenes of each scene's mean over its seeds; a failed training is counted, not
// scored; trainers are never pooled.
std::vector<SweepRow> SplatRows() {
  std::vector<SweepRow> rows = {
      Row("A", "4", "0", {{"prior", {4, 4}}}), Row("A", "4", "1", {{"prior", {4, 4}}}),
      Row("B", "4", "0", {{"prior", {4, 4}}}), Row("B", "4", "1", {{"prior", {4, 4}}})};
  // Scene A: prior 20 and 22 (mean 21), refined 24 and 26 (mean 25); scene B: prior 17 (seed 1
  // failed), refined 27 and 29 (mean 28), ground truth 30 (seed 0 only).
  rows[0].splat["splat"] = {{"prior", Training("gsplat", 20, 0.5, 0.4, 30)},
                            {"refined", Training("gsplat", 24, 0.7, 0.2, 31)}};
  rows[1].splat["splat"] = {{"prior", Training("gsplat", 22, 0.6, 0.3, 32)},
                            {"refined", Training("gsplat", 26, 0.8, 0.1, 33)}};
  rows[2].splat["splat"] = {{"prior", Training("gsplat", 17, 0.4, 0.5)},
                            {"refined", Training("gsplat", 27, 0.75, 0.15)},
                            {"ground_truth", Training("gsplat", 30, 0.9, 0.05)}};
  rows[3].splat["splat"] = {{"prior", FailedTraining("gsplat")},
                            {"refined", Training("gsplat", 29, 0.85, kNoValue)}};
  rows[0].splat["splat@inria"] = {{"prior", Training("inria", 10, 0.1, 0.9)}};
  return rows;
}

TEST(CampaignReportTest, SplatTable4IsTheMeanOverScenesPerPoseSource) {
  const CampaignReport report = AggregateCampaign(SplatRows());
  const auto find = [&](const std::string& id, const std::string& scene,
                        const std::string& pose_set) -> const SplatCell* {
    for (const SplatCell& cell : report.splat_cells) {
      if (cell.stage_id == id && cell.scene == scene && cell.pose_set == pose_set) return &cell;
    }
    return nullptr;
  };
  const SplatCell* prior = find("splat", CampaignReport::kAllScenes, "prior");
  ASSERT_NE(prior, nullptr);
  EXPECT_EQ(prior->trainer, "gsplat");
  EXPECT_EQ(prior->level_deg, 4.0);
  EXPECT_DOUBLE_EQ(prior->psnr, (21.0 + 17.0) / 2);  // not the mean of the three trainings
  EXPECT_DOUBLE_EQ(prior->ssim, (0.55 + 0.4) / 2);
  EXPECT_DOUBLE_EQ(prior->lpips, (0.35 + 0.5) / 2);
  EXPECT_DOUBLE_EQ(prior->raytime_psnr, 31.0);  // scene A only: B's trainer left no renders
  EXPECT_EQ(prior->scenes, 2);
  EXPECT_EQ(prior->scenes_tried, 2);
  EXPECT_EQ(prior->trainings, 3);
  EXPECT_EQ(prior->failed, 1);
  const SplatCell* refined = find("splat", CampaignReport::kAllScenes, "refined");
  ASSERT_NE(refined, nullptr);
  EXPECT_DOUBLE_EQ(refined->psnr, (25.0 + 28.0) / 2);
  EXPECT_DOUBLE_EQ(refined->lpips, (0.15 + 0.15) / 2);  // B's seed 1 reported none
  const SplatCell* b_refined = find("splat", "B", "refined");
  ASSERT_NE(b_refined, nullptr);
  EXPECT_DOUBLE_EQ(b_refined->psnr, 28.0);
  EXPECT_DOUBLE_EQ(b_refined->lpips, 0.15);
  const SplatCell* truth = find("splat", CampaignReport::kAllScenes, "ground_truth");
  ASSERT_NE(truth, nullptr);
  EXPECT_EQ(truth->scenes, 1);
  EXPECT_EQ(truth->scenes_tried, 1);
  EXPECT_DOUBLE_EQ(truth->psnr, 30.0);
  const SplatCell* inria = find("splat@inria", CampaignReport::kAllScenes, "prior");
  ASSERT_NE(inria, nullptr);
  EXPECT_EQ(inria->trainer, "inria");
  EXPECT_DOUBLE_EQ(inria->psnr, 10.0);

  // Report order: the prior first, ground truth last.
  std::vector<std::string> order;
  for (const SplatCell& cell : report.splat_cells) {
    if (cell.stage_id == "splat" && cell.scene == CampaignReport::kAllScenes) {
      order.push_back(cell.pose_set);
    }
  }
  EXPECT_EQ(order, (std::vector<std::string>{"prior", "refined", "ground_truth"}));

  const std::string markdown = CampaignReportMarkdown(report, "sweep.json");
  EXPECT_NE(markdown.find("## Downstream 3DGS on held-out views (Table 4 shape)"),
            std::string::npos);
  EXPECT_NE(markdown.find("### `splat` (gsplat), level 4°"), std::string::npos) << markdown;
  EXPECT_NE(markdown.find("### `splat@inria` (inria), level 4°"), std::string::npos);
  EXPECT_NE(
      markdown.find("| prior | 19.00 | 0.475 | 0.425 | 31.00 | 0.500 | 2.00 | 100 | 2/2 | 1 |"),
      std::string::npos)
      << markdown;
  EXPECT_NE(
      markdown.find("| refined | 26.50 | 0.775 | 0.150 | 32.00 | 0.500 | 2.00 | 100 | 2/2 | 0 |"),
      std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("| ground_truth | 30.00 | 0.900 | 0.050 | – | – | – | 100 | 1/1 | 0 |"),
            std::string::npos)
      << markdown;
  // The floor: scene A's two seeds of one pose source differ by 2 dB (raytime PSNR 30 and 32).
  EXPECT_NE(markdown.find("Training-noise floor: 2.00 dB"), std::string::npos) << markdown;
  // Per-scene PSNR (two scenes), with its mean row: raytime's where a training has it (gsplat),
  // the trainer's where none has (Inria), each scene's largest seed spread last.
  EXPECT_NE(markdown.find("| A | 31.00 | 32.00 | – | 2.00 |"), std::string::npos) << markdown;
  EXPECT_NE(markdown.find("| B | – | – | – | – |"), std::string::npos) << markdown;
  EXPECT_NE(markdown.find("| Mean | 31.00 | 32.00 | – | 2.00 |"), std::string::npos) << markdown;
  EXPECT_NE(markdown.find("| A | 10.00 | – |"), std::string::npos) << markdown;
  EXPECT_NE(markdown.find("Training-noise floor: not measured"), std::string::npos) << markdown;

  const std::string csv = CampaignSplatCsv(report);
  EXPECT_EQ(csv.rfind("stage,trainer,level_deg,scene,pose_set,", 0), 0u) << csv;
  EXPECT_NE(csv.find("splat,gsplat,4,(all),prior,2,2,3,1,19,0.475,0.425,31,0.5,2,100\n"),
            std::string::npos)
      << csv;
  // A sweep without splat stages has no Table 4.
  EXPECT_TRUE(AggregateCampaign(HandMadeRows()).splat_cells.empty());
  EXPECT_EQ(CampaignReportMarkdown(AggregateCampaign(HandMadeRows()), "s").find("Table 4"),
            std::string::npos);
  EXPECT_EQ(CampaignSplatCsv(AggregateCampaign(HandMadeRows())), "");
}

TEST_F(SweepFileTest, SplatResultsSurviveTheRoundTrip) {
  json rows = json::array();
  for (const SweepRow& row : SplatRows()) rows.push_back(row.ToJson());
  const std::vector<SweepRow> read = ReadSweepRows(Write(rows.dump(2)));
  ASSERT_EQ(read.size(), 4u);
  EXPECT_EQ(read[3].ToJson(), SplatRows()[3].ToJson());
  EXPECT_EQ(read[3].splat.at("splat").at("prior").status, "failed");
  EXPECT_TRUE(std::isnan(read[3].splat.at("splat").at("refined").lpips));
  EXPECT_EQ(read[0].splat.at("splat@inria").at("prior").trainer, "inria");
  // The CSV columns name the stage and the pose set.
  bool found = false;
  for (const auto& [column, value] : read[0].Columns()) {
    found = found || (column == "metrics.splat.refined.psnr" && value == "24");
  }
  EXPECT_TRUE(found);
  EXPECT_NE(ReadError(Write(R"([{"run": "r", "status": "ok", "splat": {"splat": {"prior": 3}}}])"))
                .find("splat.splat.prior is not an object"),
            std::string::npos);
}

// The run page's thumbnails: `width` wide at the image's aspect whichever reduction the decoder
// used (1/8 of a 1920-pixel frame, 1/4 of a 720-pixel one, whole for a small image, which is not
// enlarged), the colours kept, another format than JPEG and PNG decoded whole, and "" for a file
// that is no image.
TEST(RunPageThumbnail, WidthAspectAndColourWhateverTheDecodersReduction) {
  TempDir dir("thumbnail");
  const auto decode = [](const std::string& uri) {
    const std::string prefix = "data:image/jpeg;base64,";
    EXPECT_EQ(uri.rfind(prefix, 0), 0u);
    std::string base64 = uri.substr(prefix.size());
    const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::vector<unsigned char> bytes;
    unsigned value = 0;
    int bits = 0;
    for (const char c : base64) {
      if (c == '=') break;
      value = (value << 6) | static_cast<unsigned>(alphabet.find(c));
      bits += 6;
      if (bits >= 8) {
        bits -= 8;
        bytes.push_back(static_cast<unsigned char>((value >> bits) & 0xFF));
      }
    }
    return cv::imdecode(bytes, cv::IMREAD_COLOR);
  };
  for (const auto& [width, height] : {std::pair{1920, 1440}, {720, 960}, {100, 50}}) {
    SCOPED_TRACE(std::to_string(width) + "x" + std::to_string(height));
    // Blue-green-red (OpenCV's order): a thumbnail decoded in the wrong channel order or from the
    // wrong file fails the colour check.
    const cv::Mat image(height, width, CV_8UC3, cv::Scalar(200, 120, 40));
    const std::string path = dir / (std::to_string(width) + ".jpg");
    ASSERT_TRUE(cv::imwrite(path, image));
    const cv::Mat thumbnail = decode(ThumbnailDataUri(path, 160));
    ASSERT_FALSE(thumbnail.empty());
    const int expected_width = std::min(width, 160);
    EXPECT_EQ(thumbnail.cols, expected_width);
    EXPECT_NEAR(thumbnail.rows, static_cast<double>(height) * expected_width / width, 0.5);
    const cv::Scalar mean = cv::mean(thumbnail);
    EXPECT_NEAR(mean[0], 200, 6);
    EXPECT_NEAR(mean[1], 120, 6);
    EXPECT_NEAR(mean[2], 40, 6);
  }
  // A format whose header ReadImageSize does not read is decoded whole.
  const cv::Mat small(30, 40, CV_8UC3, cv::Scalar(200, 120, 40));
  const std::string bitmap = dir / "small.bmp";
  ASSERT_TRUE(cv::imwrite(bitmap, small));
  const cv::Mat bitmap_thumbnail = decode(ThumbnailDataUri(bitmap, 160));
  ASSERT_FALSE(bitmap_thumbnail.empty());
  EXPECT_EQ(bitmap_thumbnail.cols, 40);
  EXPECT_EQ(bitmap_thumbnail.rows, 30);
  const std::string text = dir / "notes.jpg";
  std::ofstream(text) << "not an image";
  EXPECT_EQ(ThumbnailDataUri(text, 160), "");
  EXPECT_EQ(ThumbnailDataUri(dir / "missing.jpg", 160), "");
}

}  // namespace
}  // namespace raytime

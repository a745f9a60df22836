// The Slurm backend of sweeps (pipelines/slurm_backend.h, issue 14) on a running cluster (CI starts
// a one-node one with scripts/slurm_local.sh start): the same sweep through the local and the
// Slurm backends gives the same sweep.csv (all but the timing columns), the scene's shared stage
// is computed by its leader only, and a resubmission submits only the run that is missing.
// Without a cluster the test is skipped, unless RAYTIME_REQUIRE_SLURM is set (CI), where it
// fails.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "tests/raytime_command.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// sweep.csv without its timing columns ("seconds", "seconds.<stage>"), which differ run to run.
std::string WithoutTimings(const std::string& csv) {
  std::vector<std::vector<std::string>> rows;
  std::stringstream lines(csv);
  std::string line;
  while (std::getline(lines, line)) {
    // Cells split at commas outside double quotes (run labels hold commas).
    std::vector<std::string> cells(1);
    bool quoted = false;
    for (const char c : line) {
      if (c == '"') quoted = !quoted;
      if (c == ',' && !quoted) {
        cells.emplace_back();
      } else {
        cells.back() += c;
      }
    }
    rows.push_back(cells);
  }
  if (rows.empty()) return "";
  std::vector<bool> keep;
  for (const std::string& name : rows[0]) {
    keep.push_back(name != "seconds" && name.rfind("seconds.", 0) != 0);
  }
  std::string out;
  for (const auto& cells : rows) {
    for (size_t c = 0; c < cells.size(); ++c) {
      if (c < keep.size() && keep[c]) out += cells[c] + ",";
    }
    out += "\n";
  }
  return out;
}

bool ClusterUp() {
  return RunShell("sinfo -h -o %t 2>/dev/null").output.find("idle") != std::string::npos;
}

TEST(SlurmSweep, SameTableAsLocalAndResubmitsOnlyWhatIsMissing) {
  if (!ClusterUp()) {
    if (std::getenv("RAYTIME_REQUIRE_SLURM") != nullptr) {
      FAIL() << "no idle Slurm node (sinfo); scripts/slurm_local.sh start makes one";
    }
    GTEST_SKIP() << "no Slurm cluster (scripts/slurm_local.sh start makes a one-node one)";
  }
  const fs::path dir =
      fs::temp_directory_path() / ("raytime_slurm_test_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path pipeline = dir / "sweep.yaml";
  // One scene (so one leader and three followers) with a stage every run shares (features).
  std::ofstream(pipeline) << "name: slurm-test\n"
                          << "dataset: {format: strecha, root: " << RAYTIME_SOURCE_DIR
                          << "/data/sample/fountain-P11}\n"
                          << R"(stages:
  - features: {max_features: 500}
  - prior: {mode: iid}
  - evaluate: {poses: [prior], alignments: [sim3, none]}
sweep:
  prior.level_deg: [0, 4]
  prior.seed: [0, 1]
)";
  const fs::path local = dir / "local";
  const fs::path slurm = dir / "slurm";
  const CommandResult local_run = RunRaytime("run " + pipeline.string() + " --workdir " +
                                             local.string() + " --jobs 1 --no_report");
  ASSERT_EQ(local_run.exit_code, 0) << local_run.output;
  const CommandResult slurm_run = RunRaytime("run " + pipeline.string() + " --workdir " +
                                             slurm.string() + " --backend slurm --wait");
  ASSERT_EQ(slurm_run.exit_code, 0) << slurm_run.output;
  const std::string local_table = WithoutTimings(ReadTextFile(local / "sweep.csv"));
  ASSERT_FALSE(local_table.empty());
  EXPECT_EQ(WithoutTimings(ReadTextFile(slurm / "sweep.csv")), local_table);
  EXPECT_TRUE(fs::exists(slurm / "report.md")) << "the collect job writes the campaign report";

  const nlohmann::json jobs = nlohmann::json::parse(ReadTextFile(slurm / "slurm" / "jobs.json"));
  EXPECT_EQ(jobs["jobs"]["leaders"]["runs"], 1);
  EXPECT_EQ(jobs["jobs"]["followers"]["runs"], 3);
  // The followers found the leader's features in the cache.
  int features_ran = 0;
  for (const auto& entry : fs::directory_iterator(slurm / "runs")) {
    const nlohmann::json summary =
        nlohmann::json::parse(ReadTextFile(entry.path() / "summary.json"));
    for (const auto& stage : summary["stages"]) {
      if (stage["id"] == "features" && stage["status"] == "ran") ++features_ran;
    }
  }
  EXPECT_EQ(features_ran, 1);

  // A lost run: the resubmission runs it alone and the table is whole again.
  const fs::path lost = slurm / "runs" / "level_deg=4,seed=1";
  ASSERT_TRUE(fs::exists(lost / "summary.json")) << "run labels changed?";
  fs::remove(lost / "summary.json");
  const CommandResult again = RunRaytime("run " + pipeline.string() + " --workdir " +
                                         slurm.string() + " --backend slurm --wait");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  const nlohmann::json resubmitted =
      nlohmann::json::parse(ReadTextFile(slurm / "slurm" / "jobs.json"));
  EXPECT_EQ(resubmitted["submitted"], 1);
  EXPECT_EQ(resubmitted["skipped"], 3);
  EXPECT_EQ(WithoutTimings(ReadTextFile(slurm / "sweep.csv")), local_table);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace raytime

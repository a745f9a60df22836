// End-to-end test of `raytime report` (SPEC §6 campaigns): a tiny real sweep on the sample scene
// (prior and evaluate only, no solver: seconds), then the report, its cells and its plots.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "tests/raytime_command.h"
#include "tests/temp_dir_test.h"

namespace fs = std::filesystem;

namespace {

using raytime::CommandResult;
using raytime::RunRaytime;

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

bool MatplotlibInstalled() {
  return std::system("/usr/bin/python3 -c 'import matplotlib' >/dev/null 2>&1") == 0;
}

class ReportCommandTest : public raytime::TempDirTest {
 protected:
  ReportCommandTest() : TempDirTest("report_test") {}

  // Two scenes (the sample and one that does not exist, so its runs fail) x levels 0 and 4 x
  // two seeds; the prior is scored against the ground truth. Returns the sweep's directory.
  std::string RunSmallSweep() {
    const fs::path pipeline = dir_ / "sweep.yaml";
    std::ofstream(pipeline) << R"(
name: report-test
dataset: {format: strecha, root: data/sample/fountain-P11}
stages:
  - prior: {mode: iid}
  - evaluate: {poses: [prior], alignments: [sim3, none]}
sweep:
  dataset.root: [data/sample/fountain-P11, data/sample/no-such-scene]
  prior.level_deg: [0, 4]
  prior.seed: [0, 1]
)";
    const std::string sweep_dir = (dir_ / "sweep").string();
    const CommandResult run = RunRaytime("run " + pipeline.string() + " --workdir " + sweep_dir +
                                         " --jobs 1 --no_report");
    // The missing scene's runs fail, so the sweep reports failure, but it writes every row.
    EXPECT_EQ(run.exit_code, 2) << run.output;
    EXPECT_TRUE(fs::exists(fs::path(sweep_dir) / "sweep.json")) << run.output;
    return sweep_dir;
  }
};

TEST_F(ReportCommandTest, ReportsCountsCellsAndPlotsOfASweep) {
  const std::string sweep_dir = RunSmallSweep();
  const fs::path out = dir_ / "report";
  const CommandResult result = RunRaytime("report --sweep " + sweep_dir + " --out " + out.string());
  ASSERT_EQ(result.exit_code, 0) << result.output;

  const std::string report = ReadFile(out / "report.md");
  EXPECT_NE(report.find("8 runs (4 ok, 4 failed)"), std::string::npos) << report;
  // The unperturbed prior is the ground truth (100 % success); at 4° every frame is 4° off, so
  // no run succeeds, and with no alignment the error is exactly the level.
  EXPECT_NE(report.find("| 0° | 2/2 (0.00°) | 2 |"), std::string::npos) << report;
  EXPECT_NE(report.find("| 4° | 0/2 ("), std::string::npos) << report;
  EXPECT_NE(report.find("| prior | 0.00° / 0.000 m | 4.00° / "), std::string::npos) << report;
  // Failed runs are counted per level and listed with their error.
  EXPECT_NE(report.find("| root=no-such-scene,level_deg=4,seed=1 | no-such-scene | 4° |"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("### fountain-P11"), std::string::npos) << report;

  const std::string cells = ReadFile(out / "report_cells.csv");
  // scene, level, arm, stage, failed runs, then sim3 runs, successes, success rate.
  EXPECT_NE(cells.find("\n(all),0,prior,prior,2,2,2,1,"), std::string::npos) << cells;
  EXPECT_NE(cells.find("\n(all),4,prior,prior,2,2,0,0,"), std::string::npos) << cells;
  EXPECT_NE(cells.find("\nfountain-P11,4,prior,prior,0,2,0,0,"), std::string::npos) << cells;

  // The campaign page (report/campaign_page.h): the same cells, a success and an error plot
  // per scene and pooled, the arm toggles, every run listed under its scene with a link to its own
  // page that resolves to a file (written now for runs that have a summary), the failed ones too.
  const std::string page = ReadFile(out / "report.html");
  EXPECT_NE(page.find("8 runs (4 ok, 4 failed)"), std::string::npos);
  EXPECT_NE(page.find("<td>0°</td><td style=\"background:rgba(44,160,44,0.5)\">2/2 ("),
            std::string::npos);
  size_t plots = 0;
  for (size_t at = page.find("<svg class=\"plot\""); at != std::string::npos;
       at = page.find("<svg class=\"plot\"", at + 1))
    ++plots;
  EXPECT_GE(plots, 3u);  // success plots of the pooled cells and both scenes, error plots beside
  EXPECT_NE(page.find("class=\"arm-toggle\" data-arm=\"prior\""), std::string::npos);
  size_t links = 0;
  for (size_t at = page.find("<a href=\""); at != std::string::npos;
       at = page.find("<a href=\"", at + 1)) {
    const size_t begin = at + 9, end = page.find('"', begin);
    const fs::path target = out / page.substr(begin, end - begin);
    EXPECT_TRUE(fs::exists(target)) << target;
    ++links;
  }
  EXPECT_EQ(links, 8u);  // every run, failed ones included: each wrote a summary and a page
  EXPECT_NE(page.find("root=no-such-scene,level_deg=4,seed=1"), std::string::npos);

  if (!MatplotlibInstalled()) GTEST_SKIP() << "no matplotlib for /usr/bin/python3: no plots";
  for (const char* plot : {"success_vs_level", "median_error_vs_level"}) {
    for (const char* extension : {".png", ".svg"}) {
      const fs::path path = out / (std::string(plot) + extension);
      ASSERT_TRUE(fs::exists(path)) << path << "\n" << result.output;
      EXPECT_GT(fs::file_size(path), 1000u) << path;
    }
  }
}

TEST_F(ReportCommandTest, MissingMatplotlibWarnsAndKeepsTheReport) {
  const std::string sweep_dir = RunSmallSweep();
  // A matplotlib package that fails to import, first on the module path.
  fs::create_directories(dir_ / "python" / "matplotlib");
  std::ofstream(dir_ / "python" / "matplotlib" / "__init__.py")
      << "raise ImportError('simulated: matplotlib is not installed')\n";
  const CommandResult result =
      RunRaytime("report --sweep " + sweep_dir, "PYTHONPATH=" + (dir_ / "python").string());
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("matplotlib is missing"), std::string::npos) << result.output;
  EXPECT_TRUE(fs::exists(fs::path(sweep_dir) / "report.md"));
  EXPECT_TRUE(fs::exists(fs::path(sweep_dir) / "report_cells.csv"));
  EXPECT_FALSE(fs::exists(fs::path(sweep_dir) / "success_vs_level.png"));
}

TEST_F(ReportCommandTest, MissingOrMalformedSweepIsNamed) {
  const std::string missing = (dir_ / "nothing").string();
  const CommandResult no_sweep = RunRaytime("report --sweep " + missing);
  EXPECT_EQ(no_sweep.exit_code, 2) << no_sweep.output;
  EXPECT_NE(no_sweep.output.find(missing + "/sweep.json"), std::string::npos) << no_sweep.output;

  fs::create_directories(dir_ / "bad");
  std::ofstream(dir_ / "bad" / "sweep.json") << "[{\"run\": \"a\", \"status\": \"ok\"},\n{\n";
  const CommandResult malformed = RunRaytime("report --sweep " + (dir_ / "bad").string());
  EXPECT_EQ(malformed.exit_code, 2) << malformed.output;
  EXPECT_NE(malformed.output.find((dir_ / "bad" / "sweep.json").string() + ":"), std::string::npos)
      << malformed.output;
  EXPECT_FALSE(fs::exists(dir_ / "bad" / "report.md"));
}

}  // namespace

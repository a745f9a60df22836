#include "report/campaign_page.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "report/html.h"

namespace raytime {
namespace {

// Arms' colours, in report order (prior first): distinct on white and for most colour vision.
const char* ArmColour(size_t index) {
  static const char* kPalette[] = {"#777777", "#1f77b4", "#d62728", "#2ca02c", "#9467bd",
                                   "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#bcbd22"};
  return kPalette[index % (sizeof(kPalette) / sizeof(kPalette[0]))];
}

std::string LevelLabel(const CampaignReport& report, double level_deg) {
  return report.level_swept ? HtmlNumber(level_deg, 4) + "°" : "(not swept)";
}

struct PlotPoint {
  size_t level = 0;  // index into report.levels
  double value = NAN;
  double lower = NAN, upper = NAN;  // whisker, NaN for none
  std::string title;
};

struct PlotSeries {
  std::string arm;
  std::string colour;
  std::vector<PlotPoint> points;
};

// One plot: the levels across at even spacing, `series` as lines with points (and whiskers), the
// y axis linear over [y_min, y_max] or logarithmic. Each series is a group the legend toggles.
std::string LinePlot(const CampaignReport& report, const std::vector<PlotSeries>& series,
                     const std::string& y_label, bool log_y, double y_min, double y_max) {
  const double width = 420, height = 240, left = 52, right = 12, top = 12, bottom = 40;
  const size_t n = std::max<size_t>(report.levels.size(), 1);
  const auto x_at = [&](size_t level) {
    return n == 1 ? left + (width - left - right) / 2
                  : left + (width - left - right) * static_cast<double>(level) / (n - 1);
  };
  const auto y_at = [&](double value) {
    const double t =
        log_y ? (std::log10(value) - std::log10(y_min)) / (std::log10(y_max) - std::log10(y_min))
              : (value - y_min) / (y_max - y_min);
    return top + (height - top - bottom) * (1.0 - std::clamp(t, 0.0, 1.0));
  };
  std::string svg = "<svg class=\"plot\" xmlns=\"http://www.w3.org/2000/svg\" width=\"" +
                    HtmlNumber(width, 4) + "\" height=\"" + HtmlNumber(height, 4) + "\">";
  // Axes, level ticks, y ticks.
  svg += "<line x1=\"" + HtmlNumber(left, 4) + "\" y1=\"" + HtmlNumber(height - bottom, 4) +
         "\" x2=\"" + HtmlNumber(width - right, 4) + "\" y2=\"" + HtmlNumber(height - bottom, 4) +
         "\" stroke=\"#444\"/><line x1=\"" + HtmlNumber(left, 4) + "\" y1=\"" + HtmlNumber(top, 4) +
         "\" x2=\"" + HtmlNumber(left, 4) + "\" y2=\"" + HtmlNumber(height - bottom, 4) +
         "\" stroke=\"#444\"/>";
  for (size_t l = 0; l < report.levels.size(); ++l) {
    svg += "<text x=\"" + HtmlNumber(x_at(l), 5) + "\" y=\"" + HtmlNumber(height - bottom + 14, 5) +
           "\" font-size=\"10\" text-anchor=\"middle\">" + LevelLabel(report, report.levels[l]) +
           "</text>";
  }
  svg += "<text x=\"" + HtmlNumber(width / 2, 5) + "\" y=\"" + HtmlNumber(height - 6, 5) +
         "\" font-size=\"11\" text-anchor=\"middle\">prior perturbation level</text>";
  std::vector<double> ticks;
  if (log_y) {
    for (double t = std::pow(10.0, std::floor(std::log10(y_min))); t <= y_max * 1.0001; t *= 10)
      if (t >= y_min * 0.9999) ticks.push_back(t);
  } else {
    for (int k = 0; k <= 4; ++k) ticks.push_back(y_min + (y_max - y_min) * k / 4);
  }
  for (const double t : ticks) {
    svg += "<text x=\"" + HtmlNumber(left - 4, 4) + "\" y=\"" + HtmlNumber(y_at(t) + 3, 5) +
           "\" font-size=\"10\" text-anchor=\"end\">" + HtmlNumber(t, 3) + "</text><line x1=\"" +
           HtmlNumber(left, 4) + "\" y1=\"" + HtmlNumber(y_at(t), 5) + "\" x2=\"" +
           HtmlNumber(width - right, 4) + "\" y2=\"" + HtmlNumber(y_at(t), 5) +
           "\" stroke=\"#eee\"/>";
  }
  svg += "<text x=\"12\" y=\"" + HtmlNumber((height - bottom + top) / 2, 5) +
         "\" font-size=\"11\" text-anchor=\"middle\" transform=\"rotate(-90 12 " +
         HtmlNumber((height - bottom + top) / 2, 5) + ")\">" + HtmlEscape(y_label) + "</text>";
  for (const PlotSeries& s : series) {
    std::string line, marks;
    for (const PlotPoint& p : s.points) {
      if (!std::isfinite(p.value) || (log_y && p.value <= 0)) continue;
      const double x = x_at(p.level), y = y_at(p.value);
      line += HtmlNumber(x, 5) + "," + HtmlNumber(y, 5) + " ";
      if (std::isfinite(p.lower) && std::isfinite(p.upper)) {
        marks += "<line x1=\"" + HtmlNumber(x, 5) + "\" y1=\"" + HtmlNumber(y_at(p.lower), 5) +
                 "\" x2=\"" + HtmlNumber(x, 5) + "\" y2=\"" + HtmlNumber(y_at(p.upper), 5) +
                 "\" stroke=\"" + s.colour + "\" stroke-opacity=\"0.5\"/>";
      }
      marks += "<circle cx=\"" + HtmlNumber(x, 5) + "\" cy=\"" + HtmlNumber(y, 5) +
               "\" r=\"3.5\" fill=\"" + s.colour + "\"><title>" + HtmlEscape(p.title) +
               "</title></circle>";
    }
    svg += "<g class=\"arm\" data-arm=\"" + HtmlEscape(s.arm) + "\"><polyline points=\"" + line +
           "\" fill=\"none\" stroke=\"" + s.colour + "\" stroke-width=\"1.5\"/>" + marks + "</g>";
  }
  return svg + "</svg>";
}

// Success rate (Sim(3) mean rotation error below the threshold) and median error per level of
// one scene (or kAllScenes), one series per arm.
std::string ScenePlots(const CampaignReport& report, const std::string& scene) {
  std::vector<PlotSeries> success, error;
  double lowest = INFINITY, highest = 0.0;
  for (size_t a = 0; a < report.arms.size(); ++a) {
    const std::string& arm = report.arms[a];
    PlotSeries s{arm, ArmColour(a), {}}, e{arm, ArmColour(a), {}};
    for (size_t l = 0; l < report.levels.size(); ++l) {
      const CampaignCell* cell = report.Find(scene, report.levels[l], arm);
      if (cell == nullptr || cell->sim3.runs == 0) continue;
      const AlignedCellStats& stats = cell->sim3;
      const ProportionInterval interval = WilsonInterval(stats.successes, stats.runs);
      const std::string where = arm + " at " + LevelLabel(report, report.levels[l]) + ": ";
      s.points.push_back(
          {l, static_cast<double>(stats.successes) / stats.runs, interval.lower, interval.upper,
           where + std::to_string(stats.successes) + "/" + std::to_string(stats.runs) +
               " succeed (Wilson 95 % " + HtmlNumber(interval.lower, 2) + "–" +
               HtmlNumber(interval.upper, 2) + ")"});
      e.points.push_back({l, stats.median_rotation_deg, NAN, NAN,
                          where + "median rotation error " + HtmlNumber(stats.median_rotation_deg) +
                              "° over " + std::to_string(stats.runs) + " run(s)"});
      if (std::isfinite(stats.median_rotation_deg) && stats.median_rotation_deg > 0) {
        lowest = std::min(lowest, stats.median_rotation_deg);
        highest = std::max(highest, stats.median_rotation_deg);
      }
    }
    success.push_back(std::move(s));
    error.push_back(std::move(e));
  }
  std::string html = LinePlot(report, success, "share of runs that succeed", false, 0.0, 1.0);
  if (highest > 0) {
    // Errors below 0.001° (an unperturbed prior scores 1e-15°) sit on the axis.
    const double y_min = std::max(1e-3, std::pow(10.0, std::floor(std::log10(lowest))));
    const double y_max = std::pow(10.0, std::ceil(std::log10(highest * 1.0001)));
    html += " " + LinePlot(report, error, "median rotation error (°, Sim(3))", true, y_min,
                           std::max(y_max, y_min * 10));
  }
  return html;
}

std::string Legend(const CampaignReport& report) {
  std::string html = "<p class=\"legend\">Arms (click to show or hide): ";
  for (size_t a = 0; a < report.arms.size(); ++a) {
    html += "<button type=\"button\" class=\"arm-toggle\" data-arm=\"" +
            HtmlEscape(report.arms[a]) + "\" style=\"border-color:" + ArmColour(a) +
            "\"><span style=\"color:" + ArmColour(a) + "\">■</span> " + HtmlEscape(report.arms[a]) +
            "</button> ";
  }
  return html + "</p>";
}

// Table 5's shape: levels × arms, "k/n (median°)", shaded by the success rate.
std::string SuccessCellsTable(const CampaignReport& report, const std::string& scene) {
  std::string html = "<table class=\"cells\"><tr><th>level</th>";
  for (const std::string& arm : report.arms) html += "<th>" + HtmlEscape(arm) + "</th>";
  html += "<th>failed runs</th></tr>";
  for (const double level : report.levels) {
    html += "<tr><td>" + LevelLabel(report, level) + "</td>";
    for (const std::string& arm : report.arms) {
      const CampaignCell* cell = report.Find(scene, level, arm);
      if (cell == nullptr || cell->sim3.runs == 0) {
        html += "<td>–</td>";
        continue;
      }
      const double rate = static_cast<double>(cell->sim3.successes) / cell->sim3.runs;
      html += "<td style=\"background:rgba(44,160,44," + HtmlNumber(0.1 + 0.4 * rate, 2) + ")\">" +
              std::to_string(cell->sim3.successes) + "/" + std::to_string(cell->sim3.runs) + " (" +
              HtmlNumber(cell->sim3.median_rotation_deg) + "°)</td>";
    }
    html += "<td>" + std::to_string(report.FailedRunsAt(scene, level)) + "</td></tr>";
  }
  return html + "</table>";
}

std::string SplatSection(const CampaignReport& report) {
  if (report.splat_cells.empty()) return "";
  std::string html = "<section id=\"splat\"><h2>Downstream 3DGS (Table 4)</h2><table>" +
                     HtmlRow({"stage", "trainer", "level", "scene", "pose source", "PSNR (dB)",
                              "SSIM", "LPIPS", "raytime PSNR", "raytime SSIM", "seed spread (dB)",
                              "time / model (s)", "trainings", "failed"},
                             "th");
  for (const SplatCell& c : report.splat_cells) {
    html += HtmlRow({HtmlEscape(c.stage_id), HtmlEscape(c.trainer), LevelLabel(report, c.level_deg),
                     HtmlEscape(c.scene), HtmlEscape(c.pose_set), HtmlNumber(c.psnr, 4),
                     HtmlNumber(c.ssim), HtmlNumber(c.lpips), HtmlNumber(c.raytime_psnr, 4),
                     HtmlNumber(c.raytime_ssim), HtmlNumber(c.seed_spread_psnr, 3),
                     HtmlNumber(c.median_seconds, 3), std::to_string(c.trainings),
                     std::to_string(c.failed)});
  }
  return html + "</table></section>";
}

// Every run of one scene: its level, other swept values, status, each arm's Sim(3) mean rotation
// error, and a link to its page.
std::string SceneRuns(const CampaignReport& report, const std::vector<SweepRow>& rows,
                      const std::map<std::string, std::string>& run_pages,
                      const std::string& scene) {
  std::vector<std::string> other_keys;
  for (const auto& [key, count] : report.pooled_keys) other_keys.push_back(key);
  std::string html = "<table class=\"runs\"><tr><th>run</th><th>level</th>";
  for (const std::string& key : other_keys) html += "<th>" + HtmlEscape(key) + "</th>";
  html += "<th>status</th>";
  for (const std::string& arm : report.arms) html += "<th>" + HtmlEscape(arm) + " (°)</th>";
  html += "</tr>";
  size_t count = 0;
  for (size_t i = 0; i < rows.size() && i < report.runs.size(); ++i) {
    const CampaignRun& run = report.runs[i];
    if (run.scene != scene) continue;
    ++count;
    const SweepRow& row = rows[i];
    const auto page = run_pages.find(run.run);
    html += "<tr><td>" +
            (page == run_pages.end()
                 ? HtmlEscape(run.run)
                 : "<a href=\"" + HtmlEscape(page->second) + "\">" + HtmlEscape(run.run) + "</a>") +
            "</td><td>" + LevelLabel(report, run.level_deg) + "</td>";
    for (const std::string& key : other_keys) {
      const std::string* value = row.Swept(key);
      html += "<td>" + HtmlEscape(value ? *value : std::string("–")) + "</td>";
    }
    html +=
        "<td class=\"status " + HtmlEscape(run.status) + "\">" + HtmlEscape(run.status) +
        (row.error.empty() ? "" : " <span title=\"" + HtmlEscape(row.error) + "\">(why)</span>") +
        "</td>";
    for (const std::string& arm : report.arms) {
      double error = NAN;
      const auto by_arm = row.errors.find(arm);
      if (by_arm != row.errors.end()) {
        const auto sim3 = by_arm->second.find("sim3");
        if (sim3 != by_arm->second.end()) error = sim3->second.mean_rotation_deg;
      }
      const bool success = std::isfinite(error) && error < report.options.success_rotation_deg;
      html += "<td" + std::string(success ? " class=\"success\"" : "") + ">" + HtmlNumber(error) +
              "</td>";
    }
    html += "</tr>";
  }
  return "<details><summary>" + HtmlEscape(scene) + ": " + std::to_string(count) +
         " run(s)</summary>" + html + "</table></details>";
}

// Shows and hides an arm's lines in every plot (the legend's buttons).
const char* kLegendScript =
    "document.querySelectorAll('.arm-toggle').forEach(function (button) {"
    "  button.addEventListener('click', function () {"
    "    var off = button.classList.toggle('off');"
    "    document.querySelectorAll('g.arm').forEach(function (group) {"
    "      if (group.dataset.arm === button.dataset.arm) group.style.display = off ? 'none' : '';"
    "    });"
    "  });"
    "});";

}  // namespace

std::string CampaignReportHtml(const CampaignReport& report, const std::vector<SweepRow>& rows,
                               const std::map<std::string, std::string>& run_pages,
                               const std::string& source) {
  const int failed = static_cast<int>(report.failed_runs.size());
  std::string html =
      "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>raytime campaign "
      "report</title><style>" +
      std::string(PageStyle()) +
      ".plot{margin:4px}.arm-toggle{border:2px solid;background:#fff;margin:2px;cursor:pointer}"
      ".arm-toggle.off{opacity:.4}td.success{background:#dfd}details{margin:.5em 0}"
      "</style></head><body><h1>Campaign report</h1><p>Sweep <code>" +
      HtmlEscape(source) + "</code>: " + std::to_string(report.total_runs) + " runs (" +
      std::to_string(report.total_runs - failed) + " ok, " + std::to_string(failed) + " failed), " +
      std::to_string(report.scenes.size()) + " scene(s) (<code>" +
      HtmlEscape(report.options.scene_key) + "</code>), " + std::to_string(report.levels.size()) +
      " level(s) (<code>" + HtmlEscape(report.options.level_key) +
      "</code>). A run succeeds for an arm when its mean rotation error after Sim(3) alignment "
      "is below " +
      HtmlNumber(report.options.success_rotation_deg) + "°.</p>" + Legend(report);
  std::vector<std::string> scenes = report.scenes;
  if (report.scenes.size() > 1) scenes.insert(scenes.begin(), CampaignReport::kAllScenes);
  html += "<section id=\"plots\"><h2>Success and error against the level</h2>";
  for (const std::string& scene : scenes) {
    html += "<h3>" + HtmlEscape(scene == CampaignReport::kAllScenes ? "All scenes" : scene) +
            "</h3>" + ScenePlots(report, scene);
  }
  html +=
      "</section><section id=\"cells\"><h2>Cells: successes / runs (median rotation error)"
      "</h2>";
  for (const std::string& scene : scenes) {
    html += "<h3>" + HtmlEscape(scene == CampaignReport::kAllScenes ? "All scenes" : scene) +
            "</h3>" + SuccessCellsTable(report, scene);
  }
  html += "</section>" + SplatSection(report) +
          "<section id=\"runs\"><h2>Runs per scene</h2><p>Each arm's mean rotation error after "
          "Sim(3) alignment, green where the run succeeds; a run links to its own page.</p>";
  for (const std::string& scene : report.scenes) html += SceneRuns(report, rows, run_pages, scene);
  if (failed > 0) {
    html += "<h3>Failed runs</h3><ul>";
    for (const FailedRun& run : report.failed_runs) {
      html += "<li>" + HtmlEscape(run.run) + " (" + HtmlEscape(run.scene) + ", " +
              LevelLabel(report, run.level_deg) + "): " + HtmlEscape(run.error) + "</li>";
    }
    html += "</ul>";
  }
  return html + "</section><script>" + kLegendScript + "</script></body></html>\n";
}

}  // namespace raytime

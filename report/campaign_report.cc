#include "report/campaign_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <tuple>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/statistics.h"
#include "report/sweep_row.h"

namespace raytime {

namespace {

// The errors one run reports for one arm under one alignment; NaN where a field is absent (a
// NaN metric is written to JSON as null).
struct RunArmErrors {
  double mean_rotation_deg = kNoValue;
  double mean_centre_m = kNoValue;
  double mean_centre_relative = kNoValue;
  double mean_relative_rotation_deg = kNoValue;
  double alignment_rotation_sigma_deg = kNoValue;
};

struct RunRecord {
  std::string label;
  std::string scene;  // display name
  double level_deg = 0.0;
  std::map<std::string, std::map<std::string, RunArmErrors>> errors;  // arm -> alignment -> ...
  std::map<std::string, double> stage_seconds;                        // stage id -> seconds
  std::map<std::string, std::string> arm_stage;  // pose set -> the stage id that wrote it
  // splat stage id -> pose set -> training (Table 4).
  std::map<std::string, std::map<std::string, SweepSplatResult>> splat;
};

std::string ArmBase(const std::string& arm) { return arm.substr(0, arm.find('@')); }

bool IsMapperArm(const std::string& arm) { return arm.find("mapper") != std::string::npos; }
bool IsControlArm(const std::string& arm) {
  return ArmBase(arm) == "classical" || IsMapperArm(arm);
}
bool IsRaytimeArm(const std::string& arm) { return ArmBase(arm) == "refined"; }

// Report order: the baseline, then the pipeline's order: bootstrap, the ray-time arms, the
// prior-seeded classical controls, the prior-free mappers, anything else. Within a group the
// known arms come first in the paper's order (§4.8: plain before GNC, the classical control before
// its tuned variant), then the others by name.
bool ArmComesFirst(const std::string& a, const std::string& b, const std::string& baseline) {
  const auto group = [&](const std::string& arm) {
    if (arm == baseline) return 0;
    if (ArmBase(arm) == "bootstrap") return 1;
    if (IsRaytimeArm(arm)) return 2;
    if (IsMapperArm(arm)) return 4;
    if (ArmBase(arm) == "classical") return 3;
    return 5;
  };
  static const std::vector<std::string> kKnownOrder = {
      "bootstrap", "refined",         "refined@plain",    "refined@gnc",
      "classical", "classical@tuned", "classical@mapper", "mapper"};
  const auto known = [](const std::string& arm) {
    return std::find(kKnownOrder.begin(), kKnownOrder.end(), arm) - kKnownOrder.begin();
  };
  if (group(a) != group(b)) return group(a) < group(b);
  if (known(a) != known(b)) return known(a) < known(b);
  return a < b;
}

// Scene display names: the last path component, or the whole value when two scenes share it.
std::map<std::string, std::string> SceneDisplayNames(const std::set<std::string>& values) {
  std::map<std::string, int> uses;
  std::map<std::string, std::string> names;
  for (const auto& value : values) {
    std::string trimmed = value;
    while (trimmed.size() > 1 && trimmed.back() == '/') trimmed.pop_back();
    names[value] = std::filesystem::path(trimmed).filename().string();
    if (names[value].empty()) names[value] = value;
    ++uses[names[value]];
  }
  for (auto& [value, name] : names) {
    if (uses[name] > 1) name = value;
  }
  return names;
}

std::string RowName(const SweepRow& row, size_t index) {
  return "sweep row " + std::to_string(index + 1) + " (run " + row.run + ")";
}

double ParseLevel(const std::string& text, const std::string& row_name, const std::string& key) {
  size_t used = 0;
  double level = 0.0;
  try {
    level = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(level)) {
    throw InputError(row_name + ": '" + key + "' must be a perturbation level in degrees, got '" +
                     text + "'");
  }
  return level;
}

AlignedCellStats AlignedStats(const std::vector<const RunRecord*>& runs, const std::string& arm,
                              const std::string& alignment, const CampaignReportOptions& options) {
  AlignedCellStats stats;
  std::vector<double> rotations, centres, relatives, relative_rotations, sigmas;
  for (const RunRecord* run : runs) {
    const auto arm_it = run->errors.find(arm);
    if (arm_it == run->errors.end()) continue;
    const auto it = arm_it->second.find(alignment);
    if (it == arm_it->second.end() || std::isnan(it->second.mean_rotation_deg)) continue;
    const RunArmErrors& errors = it->second;
    ++stats.runs;
    if (errors.mean_rotation_deg < options.success_rotation_deg) ++stats.successes;
    rotations.push_back(errors.mean_rotation_deg);
    if (!std::isnan(errors.mean_centre_m)) centres.push_back(errors.mean_centre_m);
    if (!std::isnan(errors.mean_centre_relative)) relatives.push_back(errors.mean_centre_relative);
    if (!std::isnan(errors.mean_relative_rotation_deg)) {
      relative_rotations.push_back(errors.mean_relative_rotation_deg);
    }
    if (!std::isnan(errors.alignment_rotation_sigma_deg)) {
      sigmas.push_back(errors.alignment_rotation_sigma_deg);
    }
    if (arm == options.baseline_arm) continue;
    const auto baseline_it = run->errors.find(options.baseline_arm);
    if (baseline_it == run->errors.end()) continue;
    const auto baseline = baseline_it->second.find(alignment);
    if (baseline == baseline_it->second.end() || std::isnan(baseline->second.mean_rotation_deg)) {
      continue;
    }
    ++stats.halving_runs;
    if (errors.mean_rotation_deg <= 0.5 * baseline->second.mean_rotation_deg) {
      ++stats.halves_baseline;
    }
  }
  stats.median_rotation_deg = Median(rotations, kNoValue);
  stats.median_centre_m = Median(centres, kNoValue);
  stats.median_centre_relative = Median(relatives, kNoValue);
  stats.median_relative_rotation_deg = Median(relative_rotations, kNoValue);
  stats.median_alignment_rotation_sigma_deg = Median(sigmas, kNoValue);
  return stats;
}

CampaignCell MakeCell(const std::string& scene, double level_deg, const std::string& arm,
                      const std::vector<const RunRecord*>& runs,
                      const CampaignReportOptions& options) {
  CampaignCell cell;
  cell.scene = scene;
  cell.level_deg = level_deg;
  cell.arm = arm;
  cell.sim3 = AlignedStats(runs, arm, "sim3", options);
  cell.none = AlignedStats(runs, arm, "none", options);
  std::string stage_id;
  std::vector<double> seconds;
  for (const RunRecord* run : runs) {
    const auto writer = run->arm_stage.find(arm);
    if (writer == run->arm_stage.end() || !run->errors.count(arm)) continue;
    const auto time = run->stage_seconds.find(writer->second);
    if (time == run->stage_seconds.end()) continue;
    stage_id = writer->second;
    seconds.push_back(time->second);
  }
  cell.stage_id = stage_id;
  cell.median_seconds = Median(seconds, kNoValue);
  return cell;
}

// Table 4 rows in report order: the baseline (the prior) first, ground truth last, the arms'
// order between.
bool PoseSourceComesFirst(const std::string& a, const std::string& b, const std::string& baseline) {
  const auto last = [](const std::string& pose_set) { return pose_set == "ground_truth"; };
  if (last(a) != last(b)) return last(b);
  return ArmComesFirst(a, b, baseline);
}

// Mean of the finite values; NaN when there is none.
double MeanOfFinite(const std::vector<double>& values) {
  double sum = 0.0;
  int count = 0;
  for (const double value : values) {
    if (!std::isfinite(value)) continue;
    sum += value;
    ++count;
  }
  return count > 0 ? sum / count : kNoValue;
}

// Largest minus smallest of the finite values; NaN with fewer than two.
double Spread(const std::vector<double>& values) {
  const std::vector<double> finite = FiniteValues(values);
  if (finite.size() < 2) return kNoValue;
  const auto [low, high] = std::minmax_element(finite.begin(), finite.end());
  return *high - *low;
}

// `value` if `largest` is NaN (none yet), else the larger of the two; a NaN `value` changes
// nothing.
double LargerOf(double largest, double value) {
  if (std::isnan(value)) return largest;
  return std::isnan(largest) ? value : std::max(largest, value);
}

// Averages `cells` (each a scene's) into one: each metric the mean over the cells that have it.
void AverageInto(const std::vector<const SplatCell*>& cells, SplatCell* out) {
  std::vector<double> psnr, ssim, lpips, raytime_psnr, raytime_ssim;
  for (const SplatCell* cell : cells) {
    psnr.push_back(cell->psnr);
    ssim.push_back(cell->ssim);
    lpips.push_back(cell->lpips);
    raytime_psnr.push_back(cell->raytime_psnr);
    raytime_ssim.push_back(cell->raytime_ssim);
  }
  out->psnr = MeanOfFinite(psnr);
  out->ssim = MeanOfFinite(ssim);
  out->lpips = MeanOfFinite(lpips);
  out->raytime_psnr = MeanOfFinite(raytime_psnr);
  out->raytime_ssim = MeanOfFinite(raytime_ssim);
}

// The Table 4 cells of the scored runs (see SplatCell).
std::vector<SplatCell> AggregateSplat(const std::vector<RunRecord>& runs,
                                      const std::vector<std::string>& scenes,
                                      const std::string& baseline) {
  // (stage, trainer, level) -> pose sets.
  std::map<std::tuple<std::string, std::string, double>, std::set<std::string>> groups;
  for (const RunRecord& run : runs) {
    for (const auto& [id, by_pose_set] : run.splat) {
      for (const auto& [pose_set, result] : by_pose_set) {
        groups[{id, result.trainer, run.level_deg}].insert(pose_set);
      }
    }
  }
  std::vector<SplatCell> cells;
  for (const auto& [group, pose_set_names] : groups) {
    const auto& [id, trainer, level] = group;
    std::vector<std::string> pose_sets(pose_set_names.begin(), pose_set_names.end());
    std::sort(pose_sets.begin(), pose_sets.end(), [&](const std::string& a, const std::string& b) {
      return PoseSourceComesFirst(a, b, baseline);
    });
    for (const auto& pose_set : pose_sets) {
      std::vector<SplatCell> scene_cells;
      for (const auto& scene : scenes) {
        SplatCell cell{id, trainer, level, scene, pose_set};
        std::vector<double> psnr, ssim, lpips, raytime_psnr, raytime_ssim, seconds;
        bool tried = false;
        for (const RunRecord& run : runs) {
          if (run.scene != scene || run.level_deg != level) continue;
          const auto stage = run.splat.find(id);
          if (stage == run.splat.end()) continue;
          const auto it = stage->second.find(pose_set);
          if (it == stage->second.end() || it->second.trainer != trainer) continue;
          tried = true;
          const SweepSplatResult& result = it->second;
          if (!result.ok()) {
            ++cell.failed;
            continue;
          }
          ++cell.trainings;
          psnr.push_back(result.psnr);
          ssim.push_back(result.ssim);
          lpips.push_back(result.lpips);
          raytime_psnr.push_back(result.raytime_psnr);
          raytime_ssim.push_back(result.raytime_ssim);
          if (std::isfinite(result.seconds)) seconds.push_back(result.seconds);
        }
        if (!tried) continue;
        cell.scenes_tried = 1;
        cell.scenes = cell.trainings > 0 ? 1 : 0;
        cell.psnr = MeanOfFinite(psnr);
        cell.ssim = MeanOfFinite(ssim);
        cell.lpips = MeanOfFinite(lpips);
        cell.raytime_psnr = MeanOfFinite(raytime_psnr);
        cell.raytime_ssim = MeanOfFinite(raytime_ssim);
        cell.seed_spread_psnr = Spread(raytime_psnr);
        cell.median_seconds = Median(seconds, kNoValue);
        scene_cells.push_back(cell);
      }
      SplatCell all{id, trainer, level, CampaignReport::kAllScenes, pose_set};
      std::vector<const SplatCell*> scored;
      std::vector<double> seconds;
      for (const SplatCell& cell : scene_cells) {
        all.scenes_tried += cell.scenes_tried;
        all.scenes += cell.scenes;
        all.trainings += cell.trainings;
        all.failed += cell.failed;
        if (cell.scenes > 0) scored.push_back(&cell);
        all.seed_spread_psnr = LargerOf(all.seed_spread_psnr, cell.seed_spread_psnr);
        if (std::isfinite(cell.median_seconds)) seconds.push_back(cell.median_seconds);
      }
      AverageInto(scored, &all);
      all.median_seconds = Median(seconds, kNoValue);
      cells.insert(cells.end(), scene_cells.begin(), scene_cells.end());
      cells.push_back(all);
    }
  }
  return cells;
}

// ---- Formatting ----------------------------------------------------------------------------

std::string Format(const char* format, double value) {
  if (std::isnan(value)) return "–";
  char text[64];
  std::snprintf(text, sizeof(text), format, value);
  return text;
}

std::string LevelText(const CampaignReport& report, double level_deg) {
  return report.level_swept ? Format("%g°", level_deg) : "(not swept)";
}

std::string MarkdownCell(std::string text) {
  for (char& c : text) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  std::string escaped;
  for (char c : text) escaped += c == '|' ? std::string("\\|") : std::string(1, c);
  return escaped;
}

std::string TableHeader(const std::string& first, const std::vector<std::string>& columns) {
  std::string header = "| " + first;
  std::string rule = "|---";
  for (const auto& column : columns) {
    header += " | " + MarkdownCell(column);
    rule += "|---";
  }
  return header + " |\n" + rule + "|\n";
}

std::string TableRow(const std::string& first, const std::vector<std::string>& cells) {
  std::string row = "| " + MarkdownCell(first);
  for (const auto& cell : cells) row += " | " + cell;
  return row + " |\n";
}

std::string CountText(int successes, int runs) {
  return std::to_string(successes) + "/" + std::to_string(runs);
}

std::string IntervalText(const ProportionInterval& interval) {
  return Format("%.2f", interval.lower) + "–" + Format("%.2f", interval.upper);
}

// Table 5 shape (paper §4.8): rows are levels, columns arms, cells "k/n (median°)".
std::string SuccessTable(const CampaignReport& report, const std::string& scene) {
  std::vector<std::string> columns = report.arms;
  columns.push_back("failed runs");
  std::string table = TableHeader("level", columns);
  for (const double level : report.levels) {
    std::vector<std::string> cells;
    for (const auto& arm : report.arms) {
      const CampaignCell* cell = report.Find(scene, level, arm);
      cells.push_back(cell == nullptr || cell->sim3.runs == 0
                          ? "–"
                          : CountText(cell->sim3.successes, cell->sim3.runs) + " (" +
                                Format("%.2f°", cell->sim3.median_rotation_deg) + ")");
    }
    cells.push_back(std::to_string(report.FailedRunsAt(scene, level)));
    table += TableRow(LevelText(report, level), cells);
  }
  return table;
}

// Wilson 95 % intervals over runs and, pooled over several scenes, over scenes (§4.8).
std::string WilsonTables(const CampaignReport& report) {
  std::string text =
      "Over runs (the success rate of the cells above):\n\n" + TableHeader("level", report.arms);
  for (const double level : report.levels) {
    std::vector<std::string> cells;
    for (const auto& arm : report.arms) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      cells.push_back(cell == nullptr || cell->sim3.runs == 0
                          ? "–"
                          : IntervalText(WilsonInterval(cell->sim3.successes, cell->sim3.runs)));
    }
    text += TableRow(LevelText(report, level), cells);
  }
  if (report.scenes.size() < 2) return text;
  text +=
      "\nOver scenes (failures cluster by scene, so the conservative reading counts a scene only "
      "when every one of its runs at the level succeeds; `s/S` scenes and the interval):\n\n" +
      TableHeader("level", report.arms);
  for (const double level : report.levels) {
    std::vector<std::string> cells;
    for (const auto& arm : report.arms) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      if (cell == nullptr || cell->scene_success.scenes == 0) {
        cells.push_back("–");
        continue;
      }
      const SceneSuccessCount& count = cell->scene_success;
      cells.push_back(CountText(count.scenes_all_succeed, count.scenes) + " (" +
                      IntervalText(WilsonInterval(count.scenes_all_succeed, count.scenes)) + ")");
    }
    text += TableRow(LevelText(report, level), cells);
  }
  return text;
}

std::vector<std::string> LevelColumns(const CampaignReport& report) {
  std::vector<std::string> columns;
  for (const double level : report.levels) columns.push_back(LevelText(report, level));
  return columns;
}

// The ray-time arm with the most successes over all scenes and levels (the first on a tie).
std::string BestRaytimeArm(const CampaignReport& report) {
  std::string best;
  int best_successes = -1;
  for (const auto& arm : report.arms) {
    if (!IsRaytimeArm(arm)) continue;
    int successes = 0;
    for (const double level : report.levels) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      if (cell != nullptr) successes += cell->sim3.successes;
    }
    if (successes > best_successes) {
      best = arm;
      best_successes = successes;
    }
  }
  return best;
}

// Table 6 shape (§4.8 controls): the classical controls and mappers beside the best ray-time arm.
std::string ControlsTable(const CampaignReport& report) {
  std::vector<std::string> arms;
  const std::string best = BestRaytimeArm(report);
  if (!best.empty()) arms.push_back(best);
  for (const auto& arm : report.arms) {
    if (IsControlArm(arm)) arms.push_back(arm);
  }
  if (arms.size() == (best.empty() ? 0u : 1u)) {
    return "No classical control or mapper arm was scored in this sweep.\n";
  }
  std::string table = TableHeader("arm", LevelColumns(report));
  for (const auto& arm : arms) {
    std::vector<std::string> cells;
    for (const double level : report.levels) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      cells.push_back(cell == nullptr || cell->sim3.runs == 0
                          ? "–"
                          : CountText(cell->sim3.successes, cell->sim3.runs) + ", " +
                                Format("%.2f°", cell->sim3.median_rotation_deg) + ", " +
                                Format("%.1f s", cell->median_seconds));
    }
    table += TableRow(arm == best ? arm + " (best ray-time arm)" : arm, cells);
  }
  return table;
}

// Table 8 shape (§4.9): no alignment, then Sim(3) rotation of the same runs for contrast.
std::string AbsoluteFrameTable(const CampaignReport& report) {
  const std::vector<std::string> columns = LevelColumns(report);
  std::string table =
      "Absolute frame (no alignment), `rotation° / centre m`:\n\n" + TableHeader("arm", columns);
  for (const auto& arm : report.arms) {
    std::vector<std::string> cells;
    for (const double level : report.levels) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      cells.push_back(cell == nullptr || cell->none.runs == 0
                          ? "–"
                          : Format("%.2f°", cell->none.median_rotation_deg) + " / " +
                                Format("%.3f m", cell->none.median_centre_m));
    }
    table += TableRow(arm, cells);
  }
  table += "\nSim(3)-aligned, same runs (rotation only):\n\n" + TableHeader("arm", columns);
  for (const auto& arm : report.arms) {
    std::vector<std::string> cells;
    for (const double level : report.levels) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      cells.push_back(cell == nullptr || cell->sim3.runs == 0
                          ? "–"
                          : Format("%.2f°", cell->sim3.median_rotation_deg));
    }
    table += TableRow(arm, cells);
  }
  return table;
}

// The Sim(3) rotation error beside the fit's own resolution and the alignment-free relative
// rotations, for one scene or pooled: a fit on centres that lie nearly in a plane (the Strecha
// scenes: within centimetres) turns the frame by hundredths of a degree from millimetre centre
// errors, and at small levels that turn is most of the Sim(3) number.
std::string ResolutionTable(const CampaignReport& report, const std::string& scene) {
  std::string table = TableHeader("arm", LevelColumns(report));
  for (const auto& arm : report.arms) {
    std::vector<std::string> cells;
    for (const double level : report.levels) {
      const CampaignCell* cell = report.Find(scene, level, arm);
      if (cell == nullptr || cell->sim3.runs == 0) {
        cells.push_back("–");
        continue;
      }
      const AlignedCellStats& s = cell->sim3;
      cells.push_back(Format("%.3f°", s.median_rotation_deg) +
                      (std::isnan(s.median_alignment_rotation_sigma_deg)
                           ? std::string(" ± –")
                           : Format(" ± %.3f", s.median_alignment_rotation_sigma_deg)) +
                      (std::isnan(s.median_relative_rotation_deg)
                           ? std::string()
                           : Format(" / rel. %.3f°", s.median_relative_rotation_deg)));
    }
    table += TableRow(arm, cells);
  }
  return table;
}

std::string HalvingTable(const CampaignReport& report) {
  std::string table = TableHeader("arm", LevelColumns(report));
  bool any = false;
  for (const auto& arm : report.arms) {
    if (arm == report.options.baseline_arm) continue;
    std::vector<std::string> cells;
    for (const double level : report.levels) {
      const CampaignCell* cell = report.Find(CampaignReport::kAllScenes, level, arm);
      if (cell == nullptr || (cell->sim3.halving_runs == 0 && cell->none.halving_runs == 0)) {
        cells.push_back("–");
        continue;
      }
      any = true;
      cells.push_back(CountText(cell->sim3.halves_baseline, cell->sim3.halving_runs) + " (abs. " +
                      CountText(cell->none.halves_baseline, cell->none.halving_runs) + ")");
    }
    table += TableRow(arm, cells);
  }
  if (!any) {
    return "No arm was scored beside `" + report.options.baseline_arm + "` in the same runs.\n";
  }
  return table;
}

// Table 4 shape (§4.5): per splat stage, trainer and level, pose sources x the trainer's PSNR,
// SSIM, LPIPS and raytime's PSNR, SSIM, mean over scenes, with the seed spread (the training-noise
// floor) and the time per model; then per-scene PSNR (the appendix's per-scene table) when there
// are several scenes: raytime's where any training has it (the same scorer for every trainer),
// else the trainer's.
std::string SplatTables(const CampaignReport& report) {
  std::vector<std::tuple<std::string, std::string, double>> groups;
  for (const SplatCell& cell : report.splat_cells) {
    const auto group = std::make_tuple(cell.stage_id, cell.trainer, cell.level_deg);
    if (std::find(groups.begin(), groups.end(), group) == groups.end()) groups.push_back(group);
  }
  std::string text;
  for (const auto& group : groups) {
    // Named references, not a structured binding: C++17 lambdas (below) cannot capture bindings.
    const std::string& id = std::get<0>(group);
    const std::string& trainer = std::get<1>(group);
    const double level = std::get<2>(group);
    const auto in_group = [&](const SplatCell& cell) {
      return cell.stage_id == id && cell.trainer == trainer && cell.level_deg == level;
    };
    if (groups.size() > 1 || report.level_swept) {
      text += "\n### `" + id + "` (" + trainer + ")" +
              (report.level_swept ? ", level " + LevelText(report, level) : std::string()) + "\n\n";
    } else {
      text += "\nStage `" + id + "`, trainer " + trainer + ":\n\n";
    }
    text += TableHeader("pose source",
                        {"PSNR ↑", "SSIM ↑", "LPIPS ↓", "raytime PSNR ↑", "raytime SSIM ↑",
                         "seed spread (dB)", "time / model (s)", "scenes", "failed"});
    std::vector<std::string> pose_sets;
    double floor = kNoValue;
    bool raytime = false;
    for (const SplatCell& cell : report.splat_cells) {
      if (!in_group(cell)) continue;
      raytime = raytime || std::isfinite(cell.raytime_psnr);
      if (cell.scene != CampaignReport::kAllScenes) continue;
      pose_sets.push_back(cell.pose_set);
      floor = LargerOf(floor, cell.seed_spread_psnr);
      text += TableRow(
          cell.pose_set,
          {Format("%.2f", cell.psnr), Format("%.3f", cell.ssim), Format("%.3f", cell.lpips),
           Format("%.2f", cell.raytime_psnr), Format("%.3f", cell.raytime_ssim),
           Format("%.2f", cell.seed_spread_psnr), Format("%.0f", cell.median_seconds),
           CountText(cell.scenes, cell.scenes_tried), std::to_string(cell.failed)});
    }
    text += std::isnan(floor)
                ? "\nTraining-noise floor: not measured (one scored training per scene and pose "
                  "source; sweep the trainer's seed, e.g. `splat.seed: [0, 1]`).\n"
                : "\nTraining-noise floor: " + Format("%.2f", floor) +
                      " dB, the largest seed spread of raytime PSNR (one scene's trainings of one "
                      "pose source): differences below it are not told apart.\n";
    if (report.scenes.size() < 2) continue;
    const auto value = [&](const SplatCell& cell) {
      return raytime ? cell.raytime_psnr : cell.psnr;
    };
    text += std::string(raytime ? "\nraytime PSNR" : "\nPSNR") +
            " per scene (dB; seed spread: the scene's largest over its pose sources, in the Mean "
            "row the floor):\n\n";
    std::vector<std::string> columns = pose_sets;
    columns.push_back("seed spread");
    text += TableHeader("scene", columns);
    for (const auto& scene : report.scenes) {
      std::vector<std::string> cells;
      bool any = false;
      double spread = kNoValue;
      for (const auto& pose_set : pose_sets) {
        const auto it = std::find_if(
            report.splat_cells.begin(), report.splat_cells.end(), [&](const SplatCell& cell) {
              return in_group(cell) && cell.scene == scene && cell.pose_set == pose_set;
            });
        any = any || it != report.splat_cells.end();
        cells.push_back(it == report.splat_cells.end() ? "–"
                        : it->scenes == 0              ? "failed"
                                                       : Format("%.2f", value(*it)));
        if (it != report.splat_cells.end()) spread = LargerOf(spread, it->seed_spread_psnr);
      }
      cells.push_back(Format("%.2f", spread));
      if (any) text += TableRow(scene, cells);
    }
    std::vector<std::string> means;
    for (const auto& pose_set : pose_sets) {
      const auto it = std::find_if(
          report.splat_cells.begin(), report.splat_cells.end(), [&](const SplatCell& cell) {
            return in_group(cell) && cell.scene == CampaignReport::kAllScenes &&
                   cell.pose_set == pose_set;
          });
      means.push_back(Format("%.2f", value(*it)));
    }
    means.push_back(Format("%.2f", floor));
    text += TableRow("Mean", means);
  }
  return text;
}

std::string CsvText(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

std::string CsvNumber(double value) {
  if (std::isnan(value)) return "";
  char text[64];
  std::snprintf(text, sizeof(text), "%.10g", value);
  return text;
}

// A cell per scene, level and arm with runs.
void AddSceneCells(const std::vector<RunRecord>& runs, const CampaignReportOptions& options,
                   CampaignReport* report) {
  for (const auto& scene : report->scenes) {
    for (const double level : report->levels) {
      std::vector<const RunRecord*> cell_runs;
      for (const RunRecord& run : runs) {
        if (run.scene == scene && run.level_deg == level) cell_runs.push_back(&run);
      }
      for (const auto& arm : report->arms) {
        CampaignCell cell = MakeCell(scene, level, arm, cell_runs, options);
        if (cell.sim3.runs > 0 || cell.none.runs > 0) report->cells.push_back(cell);
      }
    }
  }
}

// A cell per level and arm over every scene, with how many scenes succeed in every run (after
// AddSceneCells).
void AddPooledCells(const std::vector<RunRecord>& runs, const CampaignReportOptions& options,
                    CampaignReport* report) {
  for (const double level : report->levels) {
    std::vector<const RunRecord*> level_runs;
    for (const RunRecord& run : runs) {
      if (run.level_deg == level) level_runs.push_back(&run);
    }
    for (const auto& arm : report->arms) {
      CampaignCell cell = MakeCell(CampaignReport::kAllScenes, level, arm, level_runs, options);
      if (cell.sim3.runs == 0 && cell.none.runs == 0) continue;
      for (const auto& scene : report->scenes) {
        const CampaignCell* scene_cell = report->Find(scene, level, arm);
        if (scene_cell == nullptr || scene_cell->sim3.runs == 0) continue;
        ++cell.scene_success.scenes;
        if (scene_cell->sim3.successes == scene_cell->sim3.runs) {
          ++cell.scene_success.scenes_all_succeed;
        }
      }
      report->cells.push_back(cell);
    }
  }
}

}  // namespace

ProportionInterval WilsonInterval(int successes, int trials, double z) {
  if (trials <= 0) return {0.0, 1.0};
  const double n = trials;
  const double p = static_cast<double>(successes) / n;
  const double z2 = z * z;
  const double denominator = 1.0 + z2 / n;
  const double centre = (p + z2 / (2.0 * n)) / denominator;
  const double half_width = z / denominator * std::sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n));
  // At k = 0 and k = n the bound is exactly 0 or 1; rounding would leave 1e-17 off it.
  return {successes == 0 ? 0.0 : std::max(0.0, centre - half_width),
          successes == trials ? 1.0 : std::min(1.0, centre + half_width)};
}

const CampaignCell* CampaignReport::Find(const std::string& scene, double level_deg,
                                         const std::string& arm) const {
  for (const CampaignCell& cell : cells) {
    if (cell.scene == scene && cell.level_deg == level_deg && cell.arm == arm) return &cell;
  }
  return nullptr;
}

int CampaignReport::FailedRunsAt(const std::string& scene, double level_deg) const {
  return static_cast<int>(
      std::count_if(failed_runs.begin(), failed_runs.end(), [&](const FailedRun& run) {
        return run.level_deg == level_deg && (scene == kAllScenes || run.scene == scene);
      }));
}

CampaignReport AggregateCampaign(const std::vector<SweepRow>& rows,
                                 const CampaignReportOptions& options) {
  CampaignReport report;
  report.options = options;
  report.total_runs = static_cast<int>(rows.size());
  const auto scene_value = [&](const SweepRow& row) {
    const std::string* value = row.Swept(options.scene_key);
    return value != nullptr ? *value : std::string("(not swept)");
  };

  // Scene values first, so display names can be made unique.
  std::set<std::string> scene_values;
  std::vector<std::string> scene_order;
  for (const SweepRow& row : rows) {
    if (scene_values.insert(scene_value(row)).second) scene_order.push_back(scene_value(row));
  }
  const std::map<std::string, std::string> scene_names = SceneDisplayNames(scene_values);
  for (const auto& value : scene_order) report.scenes.push_back(scene_names.at(value));

  size_t rows_with_level = 0;
  for (const SweepRow& row : rows) rows_with_level += row.Swept(options.level_key) ? 1 : 0;
  report.level_swept = rows_with_level > 0;

  std::vector<RunRecord> runs;
  std::set<double> levels;
  std::set<std::string> arms;
  std::map<std::string, std::set<std::string>> pooled_values;
  for (size_t i = 0; i < rows.size(); ++i) {
    const SweepRow& row = rows[i];
    const std::string row_name = RowName(row, i);
    const std::string* level = row.Swept(options.level_key);
    if (report.level_swept && level == nullptr) {
      throw InputError(row_name + ": no '" + options.level_key + "' column, though other runs " +
                       "have one");
    }
    RunRecord run;
    run.label = row.run;
    run.scene = scene_names.at(scene_value(row));
    run.level_deg = report.level_swept ? ParseLevel(*level, row_name, options.level_key) : 0.0;
    levels.insert(run.level_deg);
    report.runs.push_back({row.run, run.scene, run.level_deg, row.status});
    for (const auto& [key, value] : row.swept) {
      if (key != options.scene_key && key != options.level_key) pooled_values[key].insert(value);
    }
    if (!row.Succeeded()) {
      report.failed_runs.push_back(
          {run.label, run.scene, run.level_deg,
           row.error.empty() ? std::string("(no error given)") : row.error});
      continue;
    }
    for (const auto& [arm, by_alignment] : row.errors) {
      for (const auto& [alignment, e] : by_alignment) {
        run.errors[arm][alignment] = {e.mean_rotation_deg, e.mean_centre_m, e.mean_centre_relative,
                                      e.mean_relative_rotation_deg, e.alignment_rotation_sigma_deg};
      }
      arms.insert(arm);
    }
    run.stage_seconds = row.stage_seconds;
    run.arm_stage = row.pose_set_stage;
    run.splat = row.splat;
    runs.push_back(std::move(run));
  }
  report.levels.assign(levels.begin(), levels.end());
  report.arms.assign(arms.begin(), arms.end());
  std::sort(report.arms.begin(), report.arms.end(),
            [&](const std::string& a, const std::string& b) {
              return ArmComesFirst(a, b, options.baseline_arm);
            });
  for (const auto& [key, values] : pooled_values) {
    report.pooled_keys.emplace_back(key, static_cast<int>(values.size()));
  }

  AddSceneCells(runs, options, &report);
  AddPooledCells(runs, options, &report);
  report.splat_cells = AggregateSplat(runs, report.scenes, options.baseline_arm);
  return report;
}

std::string CampaignReportMarkdown(const CampaignReport& report, const std::string& source) {
  const CampaignReportOptions& options = report.options;
  const int failed = static_cast<int>(report.failed_runs.size());
  std::string arms;
  for (const auto& arm : report.arms) arms += (arms.empty() ? "`" : ", `") + arm + "`";
  std::string pooled;
  for (const auto& [key, count] : report.pooled_keys) {
    pooled += (pooled.empty() ? "" : ", ") +
              ("`" + key + "` (" + std::to_string(count) + (count == 1 ? " value)" : " values)"));
  }

  std::string text = "# Campaign report\n\n";
  text += "Sweep: `" + source + "`: " + std::to_string(report.total_runs) + " runs (" +
          std::to_string(report.total_runs - failed) + " ok, " + std::to_string(failed) +
          " failed) over " + std::to_string(report.scenes.size()) + " scene(s) (`" +
          options.scene_key + "`) and " + std::to_string(report.levels.size()) +
          " perturbation level(s) (`" + options.level_key + "`" +
          (report.level_swept ? "" : ", not swept") +
          "). Arms (scored pose sets): " + (arms.empty() ? "none" : arms) + ".";
  if (!pooled.empty()) text += " A cell pools the runs that differ only in " + pooled + ".";
  text += "\n\n";
  text +=
      "A run **succeeds** for an arm when the mean rotation error of its poses after Sim(3) "
      "alignment (Umeyama on camera centres, with scale) is below " +
      Format("%g°", options.success_rotation_deg) + " (paper §4.8). ";
  text +=
      "Cells read `k/n (med)`: k successes out of the n runs that scored the arm, and the median "
      "over those runs of the mean Sim(3) rotation error; a median tracking the level means the "
      "arm returned the prior it was given. Runs whose status is not `ok` are not scored: they "
      "are counted per level (`failed runs`) and listed at the end. Intervals are Wilson 95 % "
      "scores.\n\n";

  text += "## Successes per level and arm, all scenes (Table 5 shape)\n\n" +
          SuccessTable(report, CampaignReport::kAllScenes);
  text += "\n## Wilson 95 % intervals on the success rate, all scenes\n\n" + WilsonTables(report);
  text +=
      "\n## Controls beside the best ray-time arm (Table 6 shape)\n\n"
      "Cells: successes, median Sim(3) rotation error, median seconds of the arm's stage.\n\n" +
      ControlsTable(report);
  text +=
      "\n## Prior's own frame (Table 8 shape)\n\n"
      "Median over runs of each run's mean error with no alignment of any kind: the frame "
      "the prior was given in (paper §4.9).\n\n" +
      AbsoluteFrameTable(report);
  text +=
      "\n## Accuracy beside the Sim(3) fit's resolution\n\n"
      "Cells: the median over runs of the mean rotation error after Sim(3), `±` the median of the "
      "fitted alignment's own rotation (RMS, from the centre errors left after the fit and the "
      "reference centres' spread: Sim(3) errors closer than this are not told apart), and "
      "`rel.` the median of the mean relative rotation error over frame pairs (no alignment).\n\n" +
      ResolutionTable(report, CampaignReport::kAllScenes);
  text +=
      "\n## Halving the prior's rotation error\n\n"
      "Runs where the arm's mean rotation error is at most half that of `" +
      options.baseline_arm +
      "` in the same run: `k/n` after Sim(3), `(abs. k/n)` in the absolute "
      "frame.\n\n" +
      HalvingTable(report);
  if (!report.splat_cells.empty()) {
    text +=
        "\n## Downstream 3DGS on held-out views (Table 4 shape)\n\n"
        "Per pose source, the trainer's own held-out PSNR / SSIM / LPIPS and raytime's PSNR / "
        "SSIM over the trainer's held-out renders (the same computation for every trainer; `–` "
        "where the trainer left none), each the mean over scenes of the scene's mean over its "
        "runs. `scenes`: scenes with a successful training out of those where it was trained; a "
        "row over fewer scenes than the others is not comparable with them. Failed trainings "
        "(`splat_failed`) are counted, never scored; trainers are never pooled.\n" +
        SplatTables(report);
  }
  if (report.scenes.size() > 1) {
    text += "\n## Per scene\n";
    for (const auto& scene : report.scenes) {
      text += "\n### " + scene + "\n\n" + SuccessTable(report, scene) +
              "\nAccuracy beside the Sim(3) fit's resolution (as above):\n\n" +
              ResolutionTable(report, scene);
    }
  }
  text += "\n## Failed runs\n\n";
  if (report.failed_runs.empty()) {
    text += "None.\n";
  } else {
    text += TableHeader("run", {"scene", "level", "error"});
    for (const FailedRun& run : report.failed_runs) {
      text += TableRow(run.run, {MarkdownCell(run.scene), LevelText(report, run.level_deg),
                                 MarkdownCell(run.error)});
    }
  }
  return text;
}

std::string CampaignCellsCsv(const CampaignReport& report) {
  std::string csv = "scene,level_deg,arm,stage,failed_runs";
  for (const char* alignment : {"sim3", "none"}) {
    const std::string a = alignment;
    csv += "," + a + "_runs," + a + "_successes," + a + "_success_rate," + a + "_wilson_lower," +
           a + "_wilson_upper," + a + "_median_rotation_deg," + a + "_median_centre_m," + a +
           "_median_centre_relative," + a + "_median_relative_rotation_deg," + a +
           "_median_alignment_rotation_sigma_deg," + a + "_halving_runs," + a + "_halves_baseline";
  }
  csv += ",median_seconds,scenes,scenes_all_succeed,scenes_wilson_lower,scenes_wilson_upper\n";
  for (const CampaignCell& cell : report.cells) {
    csv += CsvText(cell.scene) + "," + CsvNumber(cell.level_deg) + "," + CsvText(cell.arm) + "," +
           CsvText(cell.stage_id) + "," +
           std::to_string(report.FailedRunsAt(cell.scene, cell.level_deg));
    for (const AlignedCellStats* stats : {&cell.sim3, &cell.none}) {
      const ProportionInterval interval = WilsonInterval(stats->successes, stats->runs);
      csv += "," + std::to_string(stats->runs) + "," + std::to_string(stats->successes) + "," +
             CsvNumber(stats->runs > 0 ? static_cast<double>(stats->successes) / stats->runs
                                       : kNoValue) +
             "," + CsvNumber(interval.lower) + "," + CsvNumber(interval.upper) + "," +
             CsvNumber(stats->median_rotation_deg) + "," + CsvNumber(stats->median_centre_m) + "," +
             CsvNumber(stats->median_centre_relative) + "," +
             CsvNumber(stats->median_relative_rotation_deg) + "," +
             CsvNumber(stats->median_alignment_rotation_sigma_deg) + "," +
             std::to_string(stats->halving_runs) + "," + std::to_string(stats->halves_baseline);
    }
    csv += "," + CsvNumber(cell.median_seconds);
    if (cell.scene == CampaignReport::kAllScenes) {
      const SceneSuccessCount& count = cell.scene_success;
      const ProportionInterval interval = WilsonInterval(count.scenes_all_succeed, count.scenes);
      csv += "," + std::to_string(count.scenes) + "," + std::to_string(count.scenes_all_succeed) +
             "," + CsvNumber(interval.lower) + "," + CsvNumber(interval.upper);
    } else {
      csv += ",,,,";
    }
    csv += "\n";
  }
  return csv;
}

std::string CampaignSplatCsv(const CampaignReport& report) {
  if (report.splat_cells.empty()) return "";
  std::string csv =
      "stage,trainer,level_deg,scene,pose_set,scenes,scenes_tried,trainings,failed,psnr,ssim,"
      "lpips,raytime_psnr,raytime_ssim,seed_spread_psnr,median_seconds\n";
  for (const SplatCell& cell : report.splat_cells) {
    csv += CsvText(cell.stage_id) + "," + CsvText(cell.trainer) + "," + CsvNumber(cell.level_deg) +
           "," + CsvText(cell.scene) + "," + CsvText(cell.pose_set) + "," +
           std::to_string(cell.scenes) + "," + std::to_string(cell.scenes_tried) + "," +
           std::to_string(cell.trainings) + "," + std::to_string(cell.failed) + "," +
           CsvNumber(cell.psnr) + "," + CsvNumber(cell.ssim) + "," + CsvNumber(cell.lpips) + "," +
           CsvNumber(cell.raytime_psnr) + "," + CsvNumber(cell.raytime_ssim) + "," +
           CsvNumber(cell.seed_spread_psnr) + "," + CsvNumber(cell.median_seconds) + "\n";
  }
  return csv;
}

}  // namespace raytime

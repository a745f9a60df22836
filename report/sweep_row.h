// One row per run of a sweep: the run's swept values, status, stage times, pose errors,
// guardrail verdicts and warning codes. Written by the sweep runner (WORKDIR/sweep.json, and
// flattened to WORKDIR/sweep.csv) and read by the campaign report: the one place that defines
// what a row holds.
#pragma once

#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "evaluate/pose_errors.h"

namespace raytime {

// One pose set's 3DGS training in a run (the splat stage's entry metrics.<stage>.<pose set>, SPEC
// §7); NaN where the run did not report a value (a failed training reports none).
struct SweepSplatResult {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  std::string trainer;  // gsplat, inria, nerfstudio
  std::string status;   // "ok" or "failed"
  double psnr = kNone;  // the trainer's held-out metrics
  double ssim = kNone;
  double lpips = kNone;
  double raytime_psnr = kNone;  // raytime's own, over the trainer's held-out renders
  double raytime_ssim = kNone;
  double seconds = kNone;  // the trainer's wall time

  bool ok() const { return status == "ok"; }
  template <class Self, class Visitor>
  static void VisitFields(Self& self, Visitor&& v) {
    v("trainer", self.trainer);
    v("status", self.status);
    v("psnr", self.psnr);
    v("ssim", self.ssim);
    v("lpips", self.lpips);
    v("raytime_psnr", self.raytime_psnr);
    v("raytime_ssim", self.raytime_ssim);
    v("seconds", self.seconds);
  }
  // core/json_fields.h: NaN as null, absent numbers NaN.
  nlohmann::json ToJson() const;
  static SweepSplatResult FromJson(const nlohmann::json& json);
};

struct SweepRow {
  std::string run;                                         // the run's label
  std::vector<std::pair<std::string, std::string>> swept;  // "prior.level_deg" -> "4"
  // "ok", "ok_with_warnings", "failed" or "interrupted" (summary.json's status).
  std::string status;
  std::string error;
  double seconds = 0.0;                         // the run's wall time
  std::map<std::string, double> stage_seconds;  // stage id -> its own computation, also if reused
  // Pose set (arm) -> alignment -> errors, as the evaluate stage reported them (NaN: not reported).
  std::map<std::string, std::map<std::string, PoseErrorStatistics>> errors;
  std::map<std::string, std::string> pose_set_stage;  // pose set -> the stage id that wrote it
  std::map<std::string, std::vector<std::string>> guardrails_fired;  // stage id -> checks fired
  std::vector<std::string> warnings;                                 // warning codes, in order
  // splat stage id -> pose set -> its training (none when the run has no splat stage).
  std::map<std::string, std::map<std::string, SweepSplatResult>> splat;

  // A finished run whose numbers count (warnings included: they are verdicts, not failures).
  bool Succeeded() const { return status == "ok" || status == "ok_with_warnings"; }
  // The swept value of `key`, or nullptr.
  const std::string* Swept(const std::string& key) const;

  nlohmann::json ToJson() const;
  // InputError naming `where` when the object is not a sweep row.
  static SweepRow FromJson(const nlohmann::json& json, const std::string& where);
  // Flat columns for CSV: run, the swept keys, status, error, seconds, seconds.<stage>,
  // metrics.<arm>.<alignment>.<field>, metrics.<splat stage>.<pose set>.<field>,
  // guardrails.<stage>, warnings.
  std::vector<std::pair<std::string, std::string>> Columns() const;
};

// RFC 4180 field: quoted when it holds a comma, a quote or a line break.
std::string CsvField(const std::string& text);

// WORKDIR/sweep.json and WORKDIR/sweep.csv (atomically).
void WriteSweepTables(const std::string& workdir, const std::vector<SweepRow>& rows);

// The rows of a sweep.json; InputError naming the file (and line) when it does not parse or a
// row is not one.
std::vector<SweepRow> ReadSweepRows(const std::string& path);

}  // namespace raytime

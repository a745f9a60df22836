// The `splat` stage: a 3DGS trainer (gsplat, Inria, nerfstudio) run once per listed pose set on
// its trainer-ready export, WORKDIR/3dgs/<pose set>/ (export format `3dgs`), and the held-out
// metrics read back (SPEC §7; paper §4.5, Table 4). Per pose set, WORKDIR/<stage id>/ holds the
// trainer's result folder <pose set>/, its log <pose set>.log and the run's record
// <pose set>.json. A pose set whose trainer fails is a `splat_failed` warning and does not stop
// the others; metrics land in summary.json as metrics.<stage id>.<pose set>.
//
// Training takes hours on a GPU, so a rerun keeps a pose set's successful result while its
// command, trainer and export are unchanged (a fingerprint of them, in its record) and retrains
// only the rest; `raytime run --force` retrains everything.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "core/atomic_file.h"
#include "core/content_hash.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/warnings.h"
#include "core/written_files.h"
#include "pipelines/stages.h"
#include "splat/splat_trainer.h"
#include "splat/trainer_export.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// Where the export format `3dgs` writes a pose set's trainer-ready folder, below the workdir.
constexpr const char* kSplatDataRoot = "3dgs";

struct SplatStageOptions {
  SplatTrainerOptions run;  // flat keys: splat.trainer, splat.command, ...
  // Pose sets to train on, each exported as WORKDIR/3dgs/<pose set>/ by an earlier `export`.
  std::vector<std::string> poses = {"refined"};

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    run.VisitFields(v);
    v("poses", poses,
      "Pose sets to train on, each exported first as WORKDIR/3dgs/<pose set> (export format 3dgs)",
      NonEmpty());
  }
  void CheckRelations(const Requirement& require) const {
    run.CheckRelations(require);
    for (size_t i = 0; i < poses.size(); ++i) {
      const std::string& name = poses[i];
      // A pose set names folders below the workdir.
      require(name.find('/') == std::string::npos && name != "." && name != "..",
              "option 'poses': '" + name + "' is not a pose set name");
      require(std::find(poses.begin(), poses.begin() + i, name) == poses.begin() + i,
              "option 'poses': '" + name + "' is listed twice");
    }
  }
};

// Files trainers add to the folder they train on (TrainerDerivedPath) and the record of what
// raytime wrote there, whose times change with every export of the same content.
bool WrittenByTrainers(const fs::path& relative) {
  return TrainerDerivedPath(relative.generic_string()) || relative == kWrittenFilesRecord;
}

// Everything a trainer's result depends on besides the trainer installation: the command as run,
// the trainer kind, where it runs, and every file of the export (names and contents).
std::string Fingerprint(const SplatRunSummary& run, const std::string& working_dir) {
  json material = {{"trainer", run.trainer},
                   {"command", run.command},
                   {"working_dir", working_dir.empty() ? fs::current_path().string()
                                                       : fs::absolute(working_dir).string()},
                   {"files", json::object()}};
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(run.data_dir)) {
    if (!entry.is_regular_file()) continue;
    const fs::path relative = fs::relative(entry.path(), run.data_dir);
    if (!WrittenByTrainers(relative)) files.push_back(relative);
  }
  std::sort(files.begin(), files.end());
  for (const auto& file : files) {
    material["files"][file.generic_string()] =
        HashFileContents((fs::path(run.data_dir) / file).string());
  }
  return HashBytes(material.dump());
}

// What summary.json's metrics carry per pose set (the stage's summary has everything).
json MetricsEntry(const SplatRunSummary& run) {
  json entry = {{"trainer", run.trainer},
                {"status", run.status},
                {"psnr", run.psnr},
                {"ssim", run.ssim},
                {"lpips", run.lpips},
                {"raytime_psnr", run.raytime_psnr},
                {"raytime_ssim", run.raytime_ssim},
                {"raytime_images", run.raytime_images},
                {"step", run.step},
                {"seconds", run.seconds},
                {"exit_code", run.exit_code},
                {"reused", run.reused}};
  if (!run.ok()) entry["error"] = run.error;
  return entry;
}

class SplatStage : public StageWithOptions<SplatStageOptions> {
 public:
  std::string type() const override { return "splat"; }
  std::string description() const override {
    return "Train 3DGS (gsplat, Inria, nerfstudio, OpenSplat) per pose set on its export; read "
           "or render and score the held-out views (PSNR/SSIM/LPIPS)";
  }
  // The exports are written by `export` from these pose sets: a new pose set or new images
  // change the key. The exports' contents are checked per pose set (Fingerprint).
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages};
    for (const auto& name : options_.poses) inputs.push_back(PoseArtifact(name));
    return inputs;
  }
  // The trainers' folders are not in the HDF5 file a sweep's cache holds.
  bool Cacheable() const override { return false; }
  bool Complete(const StageContext& context) const override {
    for (const auto& name : options_.poses) {
      const fs::path record = RecordPath(context, name);
      if (!fs::exists(record)) return false;
      const json previous = json::parse(ReadTextFile(record.string()), nullptr, false);
      if (previous.is_discarded() || previous.value("status", "") != "ok") return false;
    }
    return true;
  }

  json Run(const StageContext& context) override {
    // Every export must be there before the first trainer starts (hours later is too late).
    std::vector<std::string> missing;
    for (const auto& name : options_.poses) {
      if (!fs::is_directory(DataDir(context, name))) missing.push_back(DataDir(context, name));
    }
    if (!missing.empty()) {
      std::string list;
      for (const auto& path : missing) list += (list.empty() ? "" : ", ") + path;
      throw InputError("splat: no trainer-ready export at " + list +
                       "; an earlier stage `export: {poses: [...], formats: [3dgs]}` writes "
                       "WORKDIR/3dgs/<pose set>");
    }
    fs::create_directories(OutputDir(context));

    json runs = json::array();
    json metrics = json::object();
    Warnings warnings;
    int failed = 0;
    for (const auto& name : options_.poses) {
      SplatJob job;
      job.pose_set = name;
      job.data_dir = DataDir(context, name);
      job.result_dir = (OutputDir(context) / name).string();
      job.log_path = (OutputDir(context) / (name + ".log")).string();

      SplatRunSummary probe;  // the command and folders as they would run, for the fingerprint
      probe.trainer = options_.run.trainer;
      probe.command = ExpandSplatCommand(options_.run, job);
      probe.data_dir = job.data_dir;
      const std::string fingerprint = Fingerprint(probe, options_.run.working_dir);
      const json previous = PreviousRecord(context, name);
      job.reuse_result = !context.force && previous.value("status", "") == "ok" &&
                         previous.value("fingerprint", "") == fingerprint &&
                         fs::is_directory(job.result_dir);

      spdlog::info(fmt::format("splat: {} on pose set '{}'{}", options_.run.trainer, name,
                               job.reuse_result
                                   ? " (unchanged since its last successful run: reading it)"
                                   : ", log " + job.log_path));
      SplatRunSummary run = RunSplatTrainer(options_.run, job);
      if (job.reuse_result && !run.ok()) {
        spdlog::warn(
            fmt::format("splat: the earlier result of '{}' does not read ({}); training again",
                        name, run.error));
        job.reuse_result = false;
        run = RunSplatTrainer(options_.run, job);
      }
      if (run.reused) {
        // The time and exit status of the run that made the result.
        run.seconds = previous.value("seconds", 0.0);
        run.exit_code = previous.value("exit_code", 0);
      }
      json record = run;
      record["fingerprint"] = fingerprint;
      WriteTextFileAtomically(RecordPath(context, name).string(), record.dump(2));

      if (run.ok()) {
        // OpenSplat reports no metric of its own: only raytime's render is scored.
        const std::string trainer_metrics =
            std::isnan(run.psnr) ? std::string("no metrics of its own")
                                 : fmt::format("PSNR {:.2f} dB, SSIM {:.3f}, LPIPS {:.3f} ({})",
                                               run.psnr, run.ssim, run.lpips, run.metrics_file);
        spdlog::info(fmt::format(
            "splat: {}: {}; raytime PSNR {:.2f} dB, SSIM {:.3f} over {} view(s){}; {:.0f} s", name,
            trainer_metrics, run.raytime_psnr, run.raytime_ssim, run.raytime_images,
            run.raytime_note.empty() ? "" : " (" + run.raytime_note + ")", run.seconds));
      } else {
        ++failed;
        warnings.push_back({"splat_failed",
                            options_.run.trainer + " failed on pose set '" + name +
                                "': " + run.error + " (log: " + run.log_path + ")",
                            {},
                            {},
                            {{"pose_set", name},
                             {"trainer", options_.run.trainer},
                             {"exit_code", run.exit_code},
                             {"timed_out", run.timed_out},
                             {"log", run.log_path}}});
      }
      metrics[name] = MetricsEntry(run);
      runs.push_back(record);
    }

    const std::string id = StageId(context);
    const json summary = {{"trainer", options_.run.trainer},
                          {"pose_sets", runs},
                          {"num_ok", static_cast<int>(options_.poses.size()) - failed},
                          {"num_failed", failed},
                          {"metrics", {{id, metrics}}},
                          {"warnings", WarningsToJson(warnings)}};
    Hdf5Writer writer(context.output_path);
    writer.WriteJson("splat_summary", summary);
    writer.Commit();
    return summary;
  }

 private:
  // "splat", or "splat@gsplat" when a pipeline runs several; a stage run alone has no id.
  std::string StageId(const StageContext& context) const {
    return context.stage_id.empty() ? type() : context.stage_id;
  }
  std::string DataDir(const StageContext& context, const std::string& pose_set) const {
    return (fs::path(context.workdir) / kSplatDataRoot / pose_set).string();
  }
  fs::path OutputDir(const StageContext& context) const {
    return fs::path(context.workdir) / StageId(context);
  }
  fs::path RecordPath(const StageContext& context, const std::string& pose_set) const {
    return OutputDir(context) / (pose_set + ".json");
  }
  json PreviousRecord(const StageContext& context, const std::string& pose_set) const {
    const fs::path path = RecordPath(context, pose_set);
    if (!fs::exists(path)) return json::object();
    const json record = json::parse(ReadTextFile(path.string()), nullptr, false);
    return record.is_object() ? record : json::object();
  }
};

}  // namespace

std::unique_ptr<Stage> CreateSplatStage() { return std::make_unique<SplatStage>(); }

}  // namespace raytime

// The `classical` stage: the classical control arm (SPEC §6; paper §4.1 "Classical control",
// §4.8). Our features and matches are exported to a COLMAP database in WORKDIR/<stage id>, so
// COLMAP runs on exactly the matches every other arm sees, then COLMAP 3.8 triangulates and
// adjusts from the prior (or maps without it) and the result becomes pose set "classical"
// ("classical@tuned" for stage "classical@tuned").
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/timing.h"
#include "evaluate/classical_control.h"
#include "formats/colmap_database.h"
#include "pipelines/stages.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

struct ClassicalStageOptions {
  std::string prior = "prior";  // pose set that seeds "triangulate" mode
  ClassicalControlOptions control;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("prior", prior, "Pose set that seeds the 'triangulate' mode", NonEmpty());
    control.VisitFields(v);  // flat keys: classical.rounds, classical.mode, ...
  }
};

class ClassicalStage : public StageWithOptions<ClassicalStageOptions> {
 public:
  std::string type() const override { return "classical"; }
  std::string description() const override {
    return "COLMAP on raytime's matches: point_triangulator + bundle_adjuster from the prior "
           "(mode triangulate, the classical control) or the prior-free mapper (mode mapper)";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages, "features", "matches"};
    if (options_.control.mode == "triangulate") inputs.push_back(PoseArtifact(options_.prior));
    return inputs;
  }
  // WORKDIR/<stage id>/ (database, COLMAP models, log) is kept for inspection, not declared as
  // an output: the result is the pose set in the stage's HDF5 file, so the stage may be skipped
  // or taken from a sweep's shared cache without it.

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    const std::vector<ImageFeatures> features =
        Hdf5Reader(context.Require("features")).ReadFeatures();
    const std::vector<PairMatches> pairs = Hdf5Reader(context.Require("matches")).ReadMatches();
    PoseSet prior;
    if (options_.control.mode == "triangulate") {
      prior = Hdf5Reader(context.Require(PoseArtifact(options_.prior))).ReadPoseSet(options_.prior);
    }

    const fs::path workdir =
        fs::path(context.workdir) / (context.stage_id.empty() ? type() : context.stage_id);
    const std::string database = (workdir / "database.db").string();
    const auto start = std::chrono::steady_clock::now();
    // The room protocol refines distortion, which needs OPENCV cameras in the database too
    // (the mapper takes its cameras from there).
    WriteColmapDatabase(database, images, features, pairs,
                        options_.control.refine_intrinsics ? "OPENCV" : "");
    const double export_s = SecondsSince(start);
    spdlog::info(fmt::format("classical: exported {} images and {} pairs to {} ({:.2f} s)",
                             images.images.size(), pairs.size(), database, export_s));

    ClassicalControlSummary control;
    const PoseSet poses =
        RunClassicalControl(database, images, prior, options_.control, workdir.string(), &control);
    spdlog::info(
        fmt::format("classical: {} mode, {} round(s), {}/{} images registered, {} points, "
                    "reprojection error {:.3f} px, {:.1f} s (log: {})",
                    control.mode, control.rounds, control.num_registered, control.num_images,
                    control.num_points, control.mean_reprojection_error_px, control.wall_time_s,
                    control.log_path));
    if (control.num_registered < control.num_images) {
      spdlog::warn(fmt::format("classical: COLMAP left {} of {} images without a pose",
                               control.num_images - control.num_registered, control.num_images));
    }

    nlohmann::json summary = control.ToJson();
    summary["database"] = database;
    summary["export_s"] = export_s;
    Hdf5Writer writer(context.output_path);
    const std::string name = context.OutputPoseSetName("classical");
    writer.WritePoseSet(name, poses, PoseRole::kRefined, MakeProvenance(*this));
    writer.WriteJson("classical_summary", summary);
    writer.Commit();
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateClassicalStage() { return std::make_unique<ClassicalStage>(); }

}  // namespace raytime

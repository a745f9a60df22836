// The `export` stage: pose sets out of the work directory in the formats users train on
// (COLMAP model for 3DGS, nerfstudio transforms.json, TUM trajectory; SPEC §7), and the
// trainer-ready 3DGS folders (format 3dgs: undistorted images, PINHOLE model, initial points from
// the ray times, split; splat/trainer_export.h).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <optional>
#include <set>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/warnings.h"
#include "core/written_files.h"
#include "formats/colmap_model.h"
#include "formats/nerfstudio.h"
#include "formats/nerfstudio_folder.h"
#include "formats/tum.h"
#include "pipelines/stages.h"
#include "refine/scene.h"
#include "splat/trainer_export.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

const std::vector<std::string> kExportFormats = {
    "colmap_text", "colmap_binary", "transforms_json", "tum", "3dgs", "nerfstudio_in_place"};

struct ExportStageOptions {
  std::vector<std::string> poses = {"prior"};
  // colmap_text -> WORKDIR/<poses>/ ; colmap_binary -> WORKDIR/<poses>_bin/ ;
  // transforms_json -> WORKDIR/<poses>_transforms.json ; tum -> WORKDIR/<poses>_tum.txt ;
  // 3dgs -> WORKDIR/3dgs/<poses>/ (trainer-ready: images, sparse/0, transforms.json, test.txt);
  // nerfstudio_in_place -> WORKDIR/transforms.json: a nerfstudio dataset's own file with only its
  // poses changed, in place of the user's (formats/nerfstudio_folder.h)
  std::vector<std::string> formats = {"colmap_text", "transforms_json"};
  // 3dgs: whose ray times become the initial points. "auto": the first of `poses` a refine stage
  // wrote them for (none: no points, with a warning); "none": no points (the paper's Table 4
  // protocol initializes every source from the same random points, §4.5); else a pose set name.
  std::string points_from = "auto";
  TrainerExportOptions trainer;
  // A refined set's frames the refine stage doubted (refine/checks/frame_verdicts.h: its matches do
  // not hold it and no trusted prior places it, its pairs are unexplained, its intrinsics look
  // wrong, ...): a trainer given a frame the solve did not place learns a wrong view. Frames no
  // solve refined, or whose pose a guardrail returned as the prior's, are never exported as
  // refined.
  bool leave_out_doubted_images = true;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("poses", poses, "Pose sets to write (e.g. refined)", NonEmpty());
    v("leave_out_doubted_images", leave_out_doubted_images,
      "Leave out of a refined set's export the frames the refine stage doubted (their verdict's "
      "reason says why: not held by the matches nor placed by a trusted prior, pairs "
      "unexplained, wrong intrinsics, ...); frames no solve refined are left out always");
    v("formats", formats,
      "colmap_text -> DIR/<poses>/, colmap_binary -> <poses>_bin/, transforms_json -> "
      "<poses>_transforms.json, tum -> <poses>_tum.txt, 3dgs -> 3dgs/<poses>/ (undistorted "
      "images, PINHOLE model, points, split), nerfstudio_in_place -> transforms.json (the "
      "nerfstudio dataset's own file, only the poses changed; one pose set)",
      NonEmpty(), OneOf(kExportFormats));
    v("points_from", points_from,
      "3dgs: pose set whose refine ray times give the initial points3D; auto = the first listed "
      "pose set that has them, none = no points",
      NonEmpty());
    trainer.VisitFields(v);  // flat keys: undistort_blank_pixels, test_every, ...
  }
  void CheckRelations(const Requirement& require) const {
    trainer.CheckRelations(require);
    require(!HasFormat("nerfstudio_in_place") || poses.size() == 1,
            "format nerfstudio_in_place writes one transforms.json in place of the dataset's: "
            "list one pose set in 'poses' (e.g. [refined])");
  }

  bool HasFormat(const std::string& format) const {
    return std::find(formats.begin(), formats.end(), format) != formats.end();
  }
  bool Has3dgs() const { return HasFormat("3dgs"); }
};

std::string ExportPath(const std::string& poses, const std::string& format) {
  if (format == "colmap_text") return poses;
  if (format == "colmap_binary") return poses + "_bin";
  if (format == "transforms_json") return poses + "_transforms.json";
  if (format == "3dgs") return "3dgs/" + poses;
  if (format == "nerfstudio_in_place") return "transforms.json";
  return poses + "_tum.txt";
}

// The file_path prefix of a transforms.json written to `path`: trainers resolve file_path from the
// file's own folder, so the dataset's image folder is given relative to it (absolute when the two
// share no root). Both are resolved as the operating system resolves them (symbolic links
// followed): a work directory reached through a link at another depth would otherwise get ".."
// steps that climb from the link's folder, not from where the file lies.
std::string ImagePrefixFor(const std::string& path, const std::string& image_root) {
  const fs::path root = fs::weakly_canonical(fs::absolute(image_root));
  const fs::path folder = fs::weakly_canonical(fs::absolute(path).parent_path());
  fs::path relative = root.lexically_relative(folder);
  if (relative.empty()) relative = root;
  std::string prefix = relative.generic_string();
  if (prefix == ".") return "";
  return prefix.back() == '/' ? prefix : prefix + "/";
}

// The refine stage's frame verdicts beside pose set `name` (kFrameVerdictsJson), by image name;
// empty for a set without them (not refined).
nlohmann::json VerdictsOf(const Hdf5Reader& reader) {
  if (!reader.HasJson(kFrameVerdictsJson)) return nlohmann::json::object();
  const nlohmann::json verdicts = reader.ReadJson(kFrameVerdictsJson);
  if (!verdicts.is_object()) {
    throw InputError(reader.path() + ": /json/" + kFrameVerdictsJson +
                     " is not an object of frame verdicts; run the refine stage again");
  }
  return verdicts;
}

// The poses of set `name` that may be exported under its name, and `verdicts` its frame verdicts
// (for the files beside them). A refined set leaves out the frames no solve refined (a prior pose
// under the name "refined" is a quiet wrong answer) and, when asked, the doubted ones; each
// left-out frame is named in a warning, with its reason. A set with nothing left is an error, so
// the run fails instead of writing an empty model; a non-finite pose is an error whatever its set.
PoseSet ExportablePoses(const StageContext& context, const std::string& name,
                        bool leave_out_doubted, nlohmann::json* verdicts, Warnings* warnings) {
  const Hdf5Reader reader(context.Require(PoseArtifact(name)));
  PoseRole role = PoseRole::kPrior;
  PoseSet poses = reader.ReadPoseSet(name, &role);
  *verdicts = role == PoseRole::kRefined ? VerdictsOf(reader) : nlohmann::json::object();
  Warning unrefined{"unrefined_not_exported", "", {}, {}, {{"pose_set", name}}};
  Warning doubted{"doubted_not_exported", "", {}, {}, {{"pose_set", name}}};
  for (const auto& [image, verdict] : verdicts->items()) {
    const std::string reason = verdict.value("reason", "");
    const bool left_out =
        !RefinedBySolve(reason) || (leave_out_doubted && verdict.value("verdict", "") == "doubted");
    if (!left_out || !poses.world_from_cam.erase(image)) continue;
    Warning& warning = !RefinedBySolve(reason) ? unrefined : doubted;
    warning.images.push_back(image);
    warning.details["reasons"][image] = reason;
  }
  std::vector<std::string> non_finite;
  for (const auto& [image, pose] : poses.world_from_cam) {
    if (!pose.rotation.coeffs().allFinite() || !pose.translation.allFinite()) {
      non_finite.push_back(image);
    }
  }
  if (!non_finite.empty()) {
    throw InputError("export: pose set '" + name + "' holds " + std::to_string(non_finite.size()) +
                     " non-finite pose(s) (" + non_finite.front() +
                     (non_finite.size() > 1 ? ", ..." : "") +
                     "); nothing is written. Its stage's summary says what went wrong");
  }
  if (unrefined.images.empty() && doubted.images.empty()) return poses;
  if (poses.world_from_cam.empty()) {
    throw InputError("export: no pose of '" + name +
                     "' is left to export (every frame was doubted or not refined; see the refine "
                     "stage's warnings and frame verdicts). Export the pose set 'prior' "
                     "explicitly if that is what you want to train on");
  }
  if (!unrefined.images.empty()) {
    unrefined.message = std::to_string(unrefined.images.size()) + " image(s) of '" + name +
                        "' were not refined (no verified pair, or a guardrail kept the prior's "
                        "pose) and are left out of its export";
    warnings->push_back(unrefined);
  }
  if (!doubted.images.empty()) {
    doubted.message = std::to_string(doubted.images.size()) + " image(s) of '" + name +
                      "' were doubted by the refine stage (details.reasons; its warnings say "
                      "why) and are left out of its export (leave_out_doubted_images)";
    warnings->push_back(doubted);
  }
  return poses;
}

// The refine stage's per-camera uncertainty of pose set `name` (/json/pose_uncertainty beside
// it), for the images of `poses` only; null when the set has none (not refined, or not computed).
nlohmann::json UncertaintyOf(const StageContext& context, const std::string& name,
                             const PoseSet& poses) {
  const Hdf5Reader reader(context.Require(PoseArtifact(name)));
  if (!reader.HasJson(kPoseUncertaintyJson)) return nullptr;
  const nlohmann::json all = reader.ReadJson(kPoseUncertaintyJson);
  nlohmann::json exported = nlohmann::json::object();
  for (const auto& [image, uncertainty] : all.items()) {
    if (poses.Has(image)) exported[image] = uncertainty;
  }
  if (exported.empty()) return nullptr;
  return {{"about",
           "sigma of each camera's rotation (degrees, RMS angle) and centre (prior length "
           "units) at the refined solution, from keypoint noise (raytime docs/uncertainty.md)"},
          {"cameras", exported}};
}

// Per image name, raytime's fields of its transforms.json frame (raytime_ keys: trainers ignore
// them): its σ, and its verdict with the reason where it is not held.
nlohmann::json RaytimeFrameFields(const nlohmann::json& uncertainty,
                                  const nlohmann::json& verdicts) {
  nlohmann::json fields = nlohmann::json::object();
  if (!uncertainty.is_null()) {
    for (const auto& [image, sigma] : uncertainty["cameras"].items()) {
      fields[image] = {{"raytime_rotation_sigma_deg", sigma["rotation_deg"]},
                       {"raytime_centre_sigma", sigma["centre"]}};
    }
  }
  for (const auto& [image, verdict] : verdicts.items()) {
    fields[image]["raytime_verdict"] = verdict.value("verdict", "");
    if (verdict.value("verdict", "") != "held") {
      fields[image]["raytime_verdict_reason"] = verdict.value("reason", "");
    }
  }
  return fields;
}

// frame_verdicts.json inside an exported folder, for a refined set: every frame's verdict, the
// ones left out of the folder's model included (so a user finds why a frame is missing).
void WriteVerdictsInto(const std::string& folder, const nlohmann::json& verdicts) {
  if (verdicts.empty()) return;
  const nlohmann::json document = {
      {"about",
       "per frame: held (its matches fix it), held_by_prior (they do not; a trusted prior places "
       "it and agrees) or doubted (left out unless leave_out_doubted_images is false), with the "
       "reason (raytime README, 'Frame verdicts')"},
      {"frames", verdicts}};
  WriteTextFileAtomically((fs::path(folder) / "frame_verdicts.json").string(),
                          document.dump(2) + "\n");
  RecordWrittenFile(folder, "frame_verdicts.json");
}

// pose_uncertainty.json inside an exported folder, when the pose set has it.
void WriteUncertaintyInto(const std::string& folder, const nlohmann::json& uncertainty) {
  if (uncertainty.is_null()) return;
  WriteTextFileAtomically((fs::path(folder) / "pose_uncertainty.json").string(),
                          uncertainty.dump(2) + "\n");
  RecordWrittenFile(folder, "pose_uncertainty.json");
}

// What a trainer derived from an earlier export of WORKDIR/3dgs/`set` (TrainerDerivedPath): moved
// to WORKDIR/stale/3dgs/`set`/ before the folder is written again, since a trainer finding it would
// use it instead of the new export's (Inria's points3D.ply, downscaled images); raytime did not
// write it, so it is moved, not deleted (an earlier move's kept under a dated name).
void MoveTrainerDerivedAside(const std::string& workdir, const std::string& set) {
  const fs::path folder = fs::path(workdir) / "3dgs" / set;
  std::error_code error;
  if (!fs::is_directory(folder, error)) return;
  for (const std::string& entry : FilesNotWritten(folder.string())) {
    if (!TrainerDerivedPath(entry)) continue;
    const fs::path to = fs::path(workdir) / "stale" / "3dgs" / set / entry;
    if (fs::exists(fs::symlink_status(to, error))) {
      fs::rename(to, DatedUnusedPath(to.string()));
    }
    fs::create_directories(to.parent_path());
    fs::rename(folder / entry, to);
    spdlog::warn(
        fmt::format("export (3dgs): moved {} to {}: a trainer derived it from the earlier "
                    "export, and would use it instead of the new one",
                    (folder / entry).string(), to.string()));
  }
}

// A self-calibrating refine's cameras of pose set `name` by image name (the images it wrote beside
// the poses); empty when the set's cameras are the dataset's.
std::map<std::string, CameraIntrinsics> RefinedCameras(const StageContext& context,
                                                       const std::string& name) {
  const Hdf5Reader reader(context.Require(PoseArtifact(name)));
  std::map<std::string, CameraIntrinsics> cameras;
  if (!reader.HasJson("refined_intrinsics") || !reader.HasImages()) return cameras;
  const ImageSet images = reader.ReadImages();
  for (const ImageInfo& image : images.images) {
    cameras[image.name] = images.cameras.at(image.camera_index);
  }
  return cameras;
}

// nerfstudio_in_place: the dataset's transforms.json with pose set `name`'s poses (and cameras,
// self-calibrated) written to WORKDIR/transforms.json, with the links its paths need. Names the
// work directory's own entries never linked over.
void WriteInPlace(const StageContext& context, const std::string& name, const PoseSet& poses,
                  const nlohmann::json& frame_fields, Warnings* warnings, nlohmann::json* result) {
  const nlohmann::json source = Hdf5Reader(context.Require(kArtifactNerfstudioTransforms))
                                    .ReadJson(kArtifactNerfstudioTransforms);
  NerfstudioUpdate update;
  update.poses = poses;
  update.cameras = RefinedCameras(context, name);
  update.frame_fields = frame_fields;
  const std::set<std::string> reserved = {"summary.json", "report.html",   "transforms.json",
                                          "stale",        "3dgs",          "splat",
                                          "refined",      "dataset_frames"};
  const NerfstudioWriteSummary written = WriteNerfstudioFolder(source.at("path").get<std::string>(),
                                                               source.at("text").get<std::string>(),
                                                               context.workdir, update, reserved);
  if (!written.absolute.empty()) {
    warnings->push_back({"nerfstudio_paths_absolute",
                         "the work directory already holds '" + written.absolute.front() +
                             "' (or it lies above the dataset's folder): paths starting with it "
                             "are written absolute in " +
                             written.path,
                         {},
                         {},
                         {{"entries", written.absolute}}});
    spdlog::warn(fmt::format("export: {}", warnings->back().message));
  }
  *result = {{"path", written.path},         {"frames_updated", written.frames_updated},
             {"left_out", written.left_out}, {"links", written.links},
             {"absolute", written.absolute}, {"intrinsics_updated", written.intrinsics_updated}};
}

class ExportStage : public StageWithOptions<ExportStageOptions> {
 public:
  std::string type() const override { return "export"; }
  std::string description() const override {
    return "Write pose sets as COLMAP models, transforms.json, TUM trajectories or trainer-ready "
           "3DGS "
           "folders";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages};
    for (const auto& name : options_.poses) inputs.push_back(PoseArtifact(name));
    if (options_.HasFormat("nerfstudio_in_place")) inputs.push_back(kArtifactNerfstudioTransforms);
    // A named source of points outside `poses` (its ray times live beside its pose set).
    const std::string& source = options_.points_from;
    if (options_.Has3dgs() && source != "auto" && source != "none" &&
        std::find(options_.poses.begin(), options_.poses.end(), source) == options_.poses.end()) {
      inputs.push_back(PoseArtifact(source));
    }
    return inputs;
  }
  // COLMAP's text model (colmap_text, and the 3dgs folders' sparse/0) splits its lines on
  // whitespace: a name with a space would be written and then misread by every trainer.
  void CheckImageNames(const std::vector<std::string>& names) const override {
    std::vector<std::string> text_formats;
    for (const std::string& format : options_.formats) {
      if (format == "colmap_text" || format == "3dgs") text_formats.push_back(format);
    }
    if (text_formats.empty()) return;
    std::vector<std::string> spaced;
    for (const std::string& name : names) {
      if (!ColmapTextHoldsName(name)) spaced.push_back(name);
    }
    if (spaced.empty()) return;
    std::string formats;
    for (const std::string& format : text_formats)
      formats += (formats.empty() ? "" : ", ") + format;
    throw InputError("export: " + std::to_string(spaced.size()) +
                     " image name(s) have whitespace ('" + spaced.front() + "'" +
                     (spaced.size() > 1 ? ", ..." : "") +
                     "), which COLMAP's text model cannot hold (export formats " + formats +
                     "); rename the images, or export colmap_binary and transforms_json instead");
  }
  std::vector<std::string> ExtraOutputs() const override {
    std::vector<std::string> outputs;
    for (const auto& name : options_.poses) {
      for (const auto& format : options_.formats) outputs.push_back(ExportPath(name, format));
    }
    return outputs;
  }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    nlohmann::json written = nlohmann::json::array();
    Warnings warnings;
    std::map<std::string, PoseSet> exportable;
    std::map<std::string, nlohmann::json> uncertainty_of;  // per pose set, null when it has none
    std::map<std::string, nlohmann::json> verdicts_of;     // per pose set, {} when it has none
    nlohmann::json result_in_place;
    for (const auto& name : options_.poses) {
      nlohmann::json& verdicts = verdicts_of[name];
      const PoseSet poses =
          ExportablePoses(context, name, options_.leave_out_doubted_images, &verdicts, &warnings);
      exportable[name] = poses;
      const nlohmann::json& uncertainty = uncertainty_of[name] =
          UncertaintyOf(context, name, poses);
      for (const auto& format : options_.formats) {
        if (format == "3dgs") continue;  // all pose sets at once, below
        const std::string path = (fs::path(context.workdir) / ExportPath(name, format)).string();
        if (format == "colmap_text") {
          WriteColmapModelText(ToColmapModel(images, poses), path);
          WriteUncertaintyInto(path, uncertainty);
          WriteVerdictsInto(path, verdicts);
        } else if (format == "colmap_binary") {
          WriteColmapModelBinary(ToColmapModel(images, poses), path);
          WriteUncertaintyInto(path, uncertainty);
          WriteVerdictsInto(path, verdicts);
        } else if (format == "nerfstudio_in_place") {
          WriteInPlace(context, name, poses, RaytimeFrameFields(uncertainty, verdicts), &warnings,
                       &result_in_place);
        } else if (format == "transforms_json") {
          std::string prefix = "images/";
          if (images.image_root.empty()) {
            warnings.push_back(
                {"image_folder_unknown",
                 "the dataset's image folder is unknown (no image_root in " +
                     context.Require(kArtifactImages) + "): " + path +
                     " names its images images/NAME, which a trainer resolves beside the file",
                 {},
                 {},
                 {{"file", path}}});
            spdlog::warn(fmt::format("export: {}", warnings.back().message));
          } else {
            prefix = ImagePrefixFor(path, images.image_root);
          }
          WriteTransformsJson(path, images, poses, prefix, nlohmann::json::object(),
                              RaytimeFrameFields(uncertainty, verdicts));
        } else {
          WriteTumTrajectory(path, poses);
        }
        spdlog::info(fmt::format("export: {} -> {}", name, path));
        written.push_back(path);
      }
    }
    nlohmann::json result = {{"written", written}};
    if (!result_in_place.is_null()) result["nerfstudio_in_place"] = result_in_place;
    if (options_.Has3dgs()) {
      std::map<std::string, nlohmann::json> frame_fields;
      for (const auto& [name, poses] : exportable) {
        frame_fields[name] = RaytimeFrameFields(uncertainty_of.at(name), verdicts_of.at(name));
      }
      const TrainerExportSummary summary =
          Export3dgs(context, images, exportable, frame_fields, &warnings);
      for (size_t k = 0; k < summary.directories.size(); ++k) {
        const std::string& name = summary.pose_sets[k];
        WriteUncertaintyInto(summary.directories[k], uncertainty_of.at(name));
        WriteVerdictsInto(summary.directories[k], verdicts_of.at(name));
        written.push_back(summary.directories[k]);
      }
      result["written"] = written;
      result["3dgs"] = summary;
    }
    // The HDF5 output records what was exported, so a skipped rerun can report it.
    Hdf5Writer writer(context.output_path);
    writer.WriteJson("exported", written);
    writer.Commit();
    result["warnings"] = WarningsToJson(warnings);
    return result;
  }

 private:
  // The trainer-ready folders of every listed pose set at once: one image list (the images with a
  // pose in every set, so that the sets differ only in their poses; the others are named in a
  // warning), one split, one set of tracks.
  TrainerExportSummary Export3dgs(const StageContext& context, const ImageSet& images,
                                  const std::map<std::string, PoseSet>& poses,
                                  const std::map<std::string, nlohmann::json>& frame_fields,
                                  Warnings* warnings) const {
    for (const auto& [name, set] : poses) MoveTrainerDerivedAside(context.workdir, name);
    ImageSet common = images;
    common.images.clear();
    Warning left_out{
        "not_in_every_pose_set", "", {}, {}, {{"missing_from", nlohmann::json::object()}}};
    for (const ImageInfo& image : images.images) {
      bool everywhere = true;
      for (const auto& [name, set] : poses) {
        if (set.Has(image.name)) continue;
        everywhere = false;
        left_out.details["missing_from"][name].push_back(image.name);
      }
      if (everywhere) {
        common.images.push_back(image);
      } else {
        left_out.images.push_back(image.name);
      }
    }
    if (common.images.empty()) {
      throw InputError("export (3dgs): no image has a pose in every listed pose set (" +
                       std::to_string(images.images.size()) +
                       " images); the exports of the pose sets must share their images");
    }
    if (!left_out.images.empty()) {
      left_out.message = std::to_string(left_out.images.size()) +
                         " image(s) lack a pose in some listed pose set and are left out of "
                         "every 3dgs export, so that all pose sets share images and split";
      warnings->push_back(left_out);
      spdlog::warn(fmt::format("export (3dgs): {}", left_out.message));
    }

    std::optional<RayTimeSource> source;
    std::string from = options_.points_from;
    if (from == "auto") {
      from = "none";
      for (const std::string& name : options_.poses) {
        if (Hdf5Reader(context.Require(PoseArtifact(name))).HasRayTimes(name)) {
          from = name;
          break;
        }
      }
    }
    if (from != "none") {
      const Hdf5Reader reader(context.Require(PoseArtifact(from)));
      if (reader.HasRayTimes(from)) {
        const auto listed = poses.find(from);
        source =
            RayTimeSource{from, listed != poses.end() ? listed->second : reader.ReadPoseSet(from),
                          reader.ReadRayTimes(from)};
      } else {
        warnings->push_back(
            {"no_initial_points",
             "pose set '" + from + "' (export.points_from) has no ray times in " + reader.path() +
                 " (a refine stage writes them beside its pose set); the 3dgs exports have no "
                 "initial points",
             {},
             {},
             {{"points_from", from}}});
        spdlog::warn(fmt::format("export (3dgs): {}", warnings->back().message));
      }
    }
    // ExportForTrainers warns when it has no source; a stated reason above says it once.
    Warnings export_warnings;
    const TrainerExportSummary summary = ExportForTrainers(
        common, poses, source, options_.trainer, (fs::path(context.workdir) / "3dgs").string(),
        &export_warnings, frame_fields);
    for (const Warning& warning : export_warnings) {
      const bool said = warning.code == "no_initial_points" && !source &&
                        std::any_of(warnings->begin(), warnings->end(),
                                    [](const Warning& w) { return w.code == "no_initial_points"; });
      if (!said && !(options_.points_from == "none" && warning.code == "no_initial_points")) {
        warnings->push_back(warning);
      }
    }
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateExportStage() { return std::make_unique<ExportStage>(); }

}  // namespace raytime

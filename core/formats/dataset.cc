#include "core/formats/dataset.h"

#include <algorithm>
#include <filesystem>

#include "core/error.h"
#include "core/formats/colmap_model.h"
#include "core/formats/nerfstudio.h"
#include "core/formats/strecha.h"
#include "core/formats/tum.h"
#include "core/intrinsics.h"
#include "core/options.h"

namespace fs = std::filesystem;

namespace raytime {

const std::vector<std::string> kPoseFileFormats = {"colmap", "nerfstudio", "tum", "strecha"};

namespace {

void SortImagesByName(ImageSet* images) {
  std::sort(images->images.begin(), images->images.end(),
            [](const ImageInfo& a, const ImageInfo& b) { return a.name < b.name; });
}

std::string FindColmapModel(const std::string& root, const std::string& model) {
  if (!model.empty()) return (fs::path(root) / model).string();
  for (const char* candidate : {"sparse/0", "sparse", ""}) {
    const fs::path dir = fs::path(root) / candidate;
    if (fs::exists(dir / "cameras.bin") || fs::exists(dir / "cameras.txt")) return dir.string();
  }
  ThrowInput(root, 0,
             "no COLMAP model found (looked for cameras.bin or cameras.txt in sparse/0, "
             "sparse and the root; set dataset.model)");
}

void CheckImagesExist(const ImageSet& images, const std::string& dataset_root) {
  std::vector<std::string> missing;
  for (const auto& image : images.images) {
    if (!fs::exists(fs::path(images.image_root) / image.name)) missing.push_back(image.name);
  }
  if (!missing.empty()) {
    ThrowInput((fs::path(images.image_root) / missing.front()).string(), 0,
               "image not found (" + std::to_string(missing.size()) + " of " +
                   std::to_string(images.images.size()) + " images of dataset " + dataset_root +
                   " are missing)");
  }
}

void AddFilesBelow(const std::string& dir, std::vector<std::string>* files) {
  if (!fs::is_directory(dir)) return;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) files->push_back(entry.path().string());
  }
}

}  // namespace

Dataset LoadDataset(const DatasetOptions& options) {
  if (options.root.empty()) throw InputError("dataset.root is not set");
  if (!fs::is_directory(options.root)) ThrowInput(options.root, 0, "dataset root is not a folder");
  Dataset dataset;
  PoseSet poses;
  if (options.format == "strecha") {
    ReadStrechaScene(options.root, &dataset.images, &poses, &dataset.warnings);
    AddFilesBelow((fs::path(options.root) / "gt_dense_cameras").string(), &dataset.files);
  } else if (options.format == "colmap") {
    const std::string model_dir = FindColmapModel(options.root, options.model);
    FromColmapModel(ReadColmapModel(model_dir), &dataset.images, &poses);
    dataset.images.image_root = (fs::path(options.root) / options.images).string();
    AddFilesBelow(model_dir, &dataset.files);
  } else if (options.format == "nerfstudio") {
    const std::string path = (fs::path(options.root) / options.transforms).string();
    ReadTransformsJson(path, &dataset.images, &poses);
    dataset.files.push_back(path);
  } else {
    throw InputError(UnknownKeyMessage("dataset.format", options.format,
                                       {"strecha", "colmap", "nerfstudio"}, "format"));
  }
  // Per-view cameras that differ only by numerical noise (DTU's K) are one camera, for every
  // format alike.
  MergeNearlyEqualCameras(&dataset.images, &dataset.warnings);
  SortImagesByName(&dataset.images);
  CheckImagesExist(dataset.images, options.root);
  for (const auto& image : dataset.images.images) {
    dataset.files.push_back((fs::path(dataset.images.image_root) / image.name).string());
  }
  std::sort(dataset.files.begin(), dataset.files.end());
  if (poses.size() > 0) dataset.ground_truth = std::move(poses);
  return dataset;
}

PoseSet ReadPoseFile(const std::string& format, const std::string& path, const ImageSet* images) {
  PoseSet poses;
  ImageSet unused;
  if (format == "colmap") {
    FromColmapModel(ReadColmapModel(path), &unused, &poses);
  } else if (format == "nerfstudio") {
    ReadTransformsJson(path, &unused, &poses);
  } else if (format == "tum") {
    poses = ReadTumTrajectory(path, images ? Names(*images) : std::vector<std::string>{});
  } else if (format == "strecha") {
    ReadStrechaScene(path, &unused, &poses);
  } else {
    throw InputError(UnknownKeyMessage("pose files", format, kPoseFileFormats, "format"));
  }
  return poses;
}

}  // namespace raytime

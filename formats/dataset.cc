#include "formats/dataset.h"
#include "core/atomic_file.h"

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <utility>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/intrinsics.h"
#include "core/options.h"
#include "formats/arkitscenes.h"
#include "formats/capture.h"
#include "formats/colmap_model.h"
#include "formats/lamar.h"
#include "formats/mobilebrick.h"
#include "formats/nerfcapture.h"
#include "formats/nerfstudio.h"
#include "formats/polycam.h"
#include "formats/record3d.h"
#include "formats/scanner3d.h"
#include "formats/scannetpp.h"
#include "formats/stray.h"
#include "formats/strecha.h"
#include "formats/tum.h"

namespace fs = std::filesystem;

namespace raytime {

const std::vector<std::string> kDatasetFormats = {
    "strecha",   "colmap",      "nerfstudio",  "record3d",         "polycam",     "stray",
    "scanner3d", "nerfcapture", "mobilebrick", "scannetpp_iphone", "arkitscenes", "lamar"};
const std::vector<std::string> kPoseFileFormats = {
    "colmap",           "nerfstudio",  "tum",       "strecha",     "record3d",
    "polycam",          "stray",       "scanner3d", "nerfcapture", "mobilebrick",
    "scannetpp_iphone", "arkitscenes", "lamar"};

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
    if (!PathExists((fs::path(images.image_root) / image.name).string()))
      missing.push_back(image.name);
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

// The transforms file of a nerfcapture export given as its folder or the file itself.
std::string TransformsPath(const std::string& path, const std::string& file) {
  return fs::is_directory(path) ? (fs::path(path) / file).string() : path;
}

// Image names end up in COLMAP models, transforms.json, HDF5 and summary.json, all UTF-8; a file
// name is bytes on Linux. Refused here, once, rather than written back altered.
void RequireUtf8Names(const std::vector<std::string>& names, const std::string& source) {
  for (const std::string& name : names) {
    const std::string invalid = DescribeInvalidUtf8(name);
    if (invalid.empty()) continue;
    ThrowInput(source, 0,
               "image name '" + name + "' is not UTF-8 text (" + invalid +
                   "); rename it: COLMAP models, transforms.json and summary.json hold names as "
                   "UTF-8");
  }
}

void RequireUtf8Names(const Dataset& dataset, const std::string& source) {
  RequireUtf8Names(Names(dataset.images), source);
  if (dataset.capture) RequireUtf8Names(Names(*dataset.capture), source);
  if (dataset.ground_truth) RequireUtf8Names(Names(*dataset.ground_truth), source);
}

// The Strecha, COLMAP and nerfstudio files state each image's size with its intrinsics; the file
// itself may be another size of the same view (a full-resolution photo among downsampled
// siblings). As the capture readers do (DatasetFromRecording): the same aspect ratio rescales
// that image's camera, with a warning `intrinsics_rescaled`; another aspect ratio is an error
// naming the file. Files whose header ReadImageSize does not read (BMP, TIFF, WEBP) are left to
// the features stage, which compares the decoded size.
void FitCamerasToImageFiles(ImageSet* images, Warnings* warnings) {
  Warning rescaled{"intrinsics_rescaled", "", {}, {}, nlohmann::json::object()};
  for (ImageInfo& image : images->images) {
    const std::string path = (fs::path(images->image_root) / image.name).string();
    ImageSize size;
    try {
      size = ReadImageSize(path);
    } catch (const InputError&) {
      continue;
    }
    if (image.width <= 0 || image.height <= 0 ||
        (size.width == image.width && size.height == image.height)) {
      continue;
    }
    RequireRescaledView(image.width, image.height, size, path, path);
    const std::string stated = std::to_string(image.width) + "x" + std::to_string(image.height);
    const std::string actual = std::to_string(size.width) + "x" + std::to_string(size.height);
    const CameraIntrinsics camera = ScaleCamera(images->cameras[image.camera_index], image.width,
                                                image.height, size.width, size.height);
    const auto same = std::find(images->cameras.begin(), images->cameras.end(), camera);
    image.camera_index = static_cast<int>(same - images->cameras.begin());
    if (same == images->cameras.end()) images->cameras.push_back(camera);
    image.width = size.width;
    image.height = size.height;
    rescaled.images.push_back(image.name);
    rescaled.details["from"] = stated;
    rescaled.details["to"] = actual;
  }
  if (rescaled.images.empty()) return;
  rescaled.message = std::to_string(rescaled.images.size()) +
                     " image(s) are another size than their intrinsics state (e.g. " +
                     rescaled.details["to"].get<std::string>() + " for " +
                     rescaled.details["from"].get<std::string>() +
                     "): focal lengths and principal points were rescaled to the images";
  warnings->push_back(rescaled);
}

}  // namespace

Dataset LoadDataset(const DatasetOptions& options) {
  if (options.root.empty()) throw InputError("dataset.root is not set");
  if (!fs::is_directory(options.root)) ThrowInput(options.root, 0, "dataset root is not a folder");
  Dataset dataset;
  PoseSet poses;  // ground truth of the strecha, colmap and nerfstudio layouts
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
    ReadTransformsJson(path, &dataset.images, &poses, &dataset.transforms_text);
    dataset.transforms_path = fs::absolute(path).lexically_normal().string();
    dataset.files.push_back(path);
    if (options.nerfstudio_poses == NerfstudioPoses::kCapture)
      dataset.capture = std::exchange(poses, PoseSet());
  } else if (options.format == "record3d") {
    dataset = DatasetFromRecording(ReadRecord3d(options.root));
  } else if (options.format == "polycam") {
    dataset = DatasetFromRecording(ReadPolycam(options.root));
  } else if (options.format == "scanner3d") {
    dataset = DatasetFromRecording(ReadScanner3d(options.root));
  } else if (options.format == "nerfcapture") {
    dataset =
        DatasetFromRecording(ReadNerfCapture(TransformsPath(options.root, options.transforms)));
  } else if (options.format == "mobilebrick") {
    dataset = DatasetFromRecording(ReadMobileBrick(options.root));
  } else if (options.format == "scannetpp_iphone") {
    dataset = DatasetFromRecording(ReadScanNetPPIphone(options.root));
  } else if (options.format == "arkitscenes") {
    dataset = DatasetFromRecording(ReadArkitScenes(options.root, options.timestamps));
  } else if (options.format == "lamar") {
    dataset = DatasetFromRecording(ReadLamar(options.root, options.timestamps));
  } else if (options.format == "stray") {
    // The frames are decoded by the caller (AttachVideoFrames); nothing more to check here.
    dataset = ReadStray(options.root);
    std::sort(dataset.files.begin(), dataset.files.end());
    RequireUtf8Names(dataset, options.root);
    return dataset;
  } else {
    throw InputError(
        UnknownKeyMessage("dataset.format", options.format, kDatasetFormats, "format"));
  }
  CheckImagesExist(dataset.images, options.root);
  if (options.format == "strecha" || options.format == "colmap" || options.format == "nerfstudio") {
    FitCamerasToImageFiles(&dataset.images, &dataset.warnings);
  }
  // Per-view cameras that differ only by numerical noise (DTU's K) are one camera, for every
  // format alike.
  MergeNearlyEqualCameras(&dataset.images, &dataset.warnings);
  SortImagesByName(&dataset.images);
  for (const auto& image : dataset.images.images) {
    dataset.files.push_back((fs::path(dataset.images.image_root) / image.name).string());
  }
  std::sort(dataset.files.begin(), dataset.files.end());
  if (poses.size() > 0) dataset.ground_truth = std::move(poses);
  RequireUtf8Names(dataset, options.root);
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
  } else if (format == "record3d") {
    poses = PosesOfRecording(ReadRecord3d(path));
  } else if (format == "polycam") {
    poses = PosesOfRecording(ReadPolycam(path));
  } else if (format == "scanner3d") {
    poses = PosesOfRecording(ReadScanner3d(path));
  } else if (format == "nerfcapture") {
    poses = PosesOfRecording(ReadNerfCapture(TransformsPath(path, "transforms.json")));
  } else if (format == "stray") {
    poses = ReadStrayPoses(path);
  } else if (format == "mobilebrick") {
    poses = PosesOfRecording(ReadMobileBrick(path));
  } else if (format == "scannetpp_iphone") {
    poses = PosesOfRecording(ReadScanNetPPIphone(path));
  } else if (format == "arkitscenes") {
    poses = PosesOfRecording(ReadArkitScenes(path, TimestampJoinOptions()));
  } else if (format == "lamar") {
    poses = PosesOfRecording(ReadLamar(path, TimestampJoinOptions()));
  } else {
    throw InputError(UnknownKeyMessage("pose files", format, kPoseFileFormats, "format"));
  }
  RequireUtf8Names(Names(poses), path);
  return poses;
}

PoseSet ReadPoseFileOrSet(const std::string& format, const std::string& path,
                          const std::string& pose_set, const std::string& choose) {
  if (format != "hdf5") return ReadPoseFile(format, path);
  const Hdf5Reader reader(path);
  std::string name = pose_set;
  if (name.empty()) {
    const std::vector<std::string> names = reader.PoseSetNames();
    if (names.size() != 1) {
      ThrowInput(path, 0,
                 "holds " + std::to_string(names.size()) + " pose sets: choose one " + choose);
    }
    name = names.front();
  }
  return reader.ReadPoseSet(name);
}

}  // namespace raytime

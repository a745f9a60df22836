#include "formats/capture.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/intrinsics.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

namespace {

std::string Short(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", value);
  return buffer;
}

// Big-endian / little-endian unsigned integers of `n` bytes.
uint32_t ReadUnsigned(const std::vector<uint8_t>& bytes, size_t at, int n, bool big_endian) {
  uint32_t value = 0;
  for (int i = 0; i < n; ++i) {
    const uint32_t byte = bytes[at + (big_endian ? i : n - 1 - i)];
    value = (value << 8) | byte;
  }
  return value;
}

// EXIF orientation (1-8) of an APP1 segment's payload, 1 when absent or unreadable.
int ExifOrientation(const std::vector<uint8_t>& segment) {
  static const char kExif[] = {'E', 'x', 'i', 'f', 0, 0};
  if (segment.size() < 14 || !std::equal(kExif, kExif + 6, segment.begin())) return 1;
  const size_t tiff = 6;
  const bool big = segment[tiff] == 'M' && segment[tiff + 1] == 'M';
  if (!big && !(segment[tiff] == 'I' && segment[tiff + 1] == 'I')) return 1;
  const uint32_t ifd = ReadUnsigned(segment, tiff + 4, 4, big);
  if (tiff + ifd + 2 > segment.size()) return 1;
  const uint32_t entries = ReadUnsigned(segment, tiff + ifd, 2, big);
  for (uint32_t e = 0; e < entries; ++e) {
    const size_t entry = tiff + ifd + 2 + 12 * e;
    if (entry + 12 > segment.size()) return 1;
    if (ReadUnsigned(segment, entry, 2, big) == 0x0112) {
      const int orientation = static_cast<int>(ReadUnsigned(segment, entry + 8, 2, big));
      return orientation >= 1 && orientation <= 8 ? orientation : 1;
    }
  }
  return 1;
}

ImageSize ReadJpegSize(const std::string& path, std::ifstream& in) {
  int orientation = 1;
  in.seekg(2);
  while (in) {
    int byte = in.get();
    if (byte != 0xFF) break;
    int marker = in.get();
    while (marker == 0xFF) marker = in.get();                      // fill bytes
    if (marker == EOF || marker == 0xD9 || marker == 0xDA) break;  // end of image, start of scan
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;  // no length
    uint8_t length_bytes[2];
    if (!in.read(reinterpret_cast<char*>(length_bytes), 2)) break;
    const int length = (length_bytes[0] << 8) | length_bytes[1];
    if (length < 2) break;
    std::vector<uint8_t> segment(static_cast<size_t>(length - 2));
    if (!in.read(reinterpret_cast<char*>(segment.data()),
                 static_cast<std::streamsize>(segment.size()))) {
      break;
    }
    if (marker == 0xE1) orientation = std::max(orientation, ExifOrientation(segment));
    // SOF0..SOF15 except DHT (C4), JPG (C8) and DAC (CC): precision, height, width.
    const bool frame =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (frame && segment.size() >= 5) {
      ImageSize size{static_cast<int>(ReadUnsigned(segment, 3, 2, true)),
                     static_cast<int>(ReadUnsigned(segment, 1, 2, true))};
      if (size.width <= 0 || size.height <= 0) break;
      if (orientation >= 5) std::swap(size.width, size.height);  // transposed by the decoder
      size.exif_orientation = orientation;
      return size;
    }
  }
  ThrowInput(path, 0, "damaged JPEG: no frame header (SOF) before the image data");
}

}  // namespace

const Eigen::Matrix3d& ArkitFromOpenCvAxes() {
  static const Eigen::Matrix3d flip = Eigen::Vector3d(1, -1, -1).asDiagonal();
  return flip;
}

Eigen::Matrix3d FromArkitIntrinsics(const Eigen::Matrix3d& K) {
  Eigen::Matrix3d shifted = K;
  shifted(0, 2) -= 0.5;
  shifted(1, 2) -= 0.5;
  return shifted;
}

json ReadJsonFile(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "file not found");
  try {
    return json::parse(ReadTextFile(path));
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number like 1e999
    ThrowInput(path, 0, std::string("not valid JSON: ") + e.what());
  }
}

double JsonNumber(const json& object, const std::string& key, const std::string& path,
                  const std::string& where) {
  const std::string prefix = where.empty() ? "" : where + ": ";
  if (!object.is_object() || !object.contains(key)) {
    ThrowInput(path, 0, prefix + "missing \"" + key + "\" (a number)");
  }
  const json& value = object[key];
  if (!value.is_number() || !std::isfinite(value.get<double>())) {
    ThrowInput(path, 0, prefix + "\"" + key + "\" must be a finite number, got " + value.dump());
  }
  return value.get<double>();
}

std::vector<double> JsonNumbers(const json& object, const std::string& key, int count,
                                const std::string& path, const std::string& where) {
  const std::string prefix = where.empty() ? "" : where + ": ";
  const std::string expected =
      count < 0 ? "an array of numbers" : "an array of " + std::to_string(count) + " numbers";
  if (!object.is_object() || !object.contains(key)) {
    ThrowInput(path, 0, prefix + "missing \"" + key + "\" (" + expected + ")");
  }
  const json& value = object[key];
  if (!value.is_array() || (count >= 0 && value.size() != static_cast<size_t>(count))) {
    const std::string got = value.is_array() ? "an array of " + std::to_string(value.size())
                                             : std::string(value.type_name());
    ThrowInput(path, 0, prefix + "\"" + key + "\" must be " + expected + ", got " + got);
  }
  std::vector<double> numbers;
  for (size_t i = 0; i < value.size(); ++i) {
    if (!value[i].is_number() || !std::isfinite(value[i].get<double>())) {
      ThrowInput(path, 0,
                 prefix + "\"" + key + "\"[" + std::to_string(i) +
                     "] is not a finite number: " + value[i].dump());
    }
    numbers.push_back(value[i].get<double>());
  }
  return numbers;
}

int PixelSize(double value, const std::string& path, int line, const std::string& what) {
  if (!(value >= 1 && value <= 1e9 && value == std::floor(value))) {
    ThrowInput(
        path, line,
        what + " must be a positive whole number of pixels (at most 1e9), got " + Short(value));
  }
  return static_cast<int>(value);
}

std::vector<double> ReadNumbersFile(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "file not found");
  return text::ParseNumbers(path, ReadTextFile(path)).values;
}

Rigid3 PoseFromCameraToWorld(const Eigen::Matrix3d& world_from_cam, const Eigen::Vector3d& centre,
                             const std::string& path, const std::string& where) {
  const std::string prefix = where.empty() ? "" : where + ": ";
  if (!world_from_cam.allFinite() || !centre.allFinite()) {
    ThrowInput(path, 0, prefix + "pose has a value that is not finite");
  }
  const std::string problem = RotationMatrixProblem(world_from_cam);
  if (!problem.empty()) ThrowInput(path, 0, prefix + "camera-to-world pose: " + problem);
  return Rigid3(Eigen::Quaterniond(Orthonormalize(world_from_cam)), centre);
}

Rigid3 PoseFromArkitCameraToWorld(const Eigen::Matrix3d& world_from_arkit_cam,
                                  const Eigen::Vector3d& centre, const std::string& path,
                                  const std::string& where) {
  return PoseFromCameraToWorld(world_from_arkit_cam * ArkitFromOpenCvAxes(), centre, path, where);
}

ImageSize ReadImageSize(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInput(path, 0, "image not found or not readable");
  uint8_t head[24] = {};
  in.read(reinterpret_cast<char*>(head), sizeof(head));
  const std::streamsize got = in.gcount();
  if (got >= 3 && head[0] == 0xFF && head[1] == 0xD8 && head[2] == 0xFF) {
    in.clear();
    return ReadJpegSize(path, in);
  }
  static const uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (got >= 24 && std::equal(kPng, kPng + 8, head)) {
    const std::vector<uint8_t> bytes(head, head + 24);
    const ImageSize size{static_cast<int>(ReadUnsigned(bytes, 16, 4, true)),
                         static_cast<int>(ReadUnsigned(bytes, 20, 4, true))};
    if (size.width <= 0 || size.height <= 0) ThrowInput(path, 0, "damaged PNG header");
    return size;
  }
  ThrowInput(path, 0, "not a JPEG or PNG image (cannot read its size from the header)");
}

std::string ExifOrientationNote(const ImageSize& size) {
  if (size.exif_orientation == 1) return "";
  return " (its EXIF orientation tag is " + std::to_string(size.exif_orientation) +
         (size.exif_orientation >= 5
              ? ": decoders turn it by 90°, so it reads as " + std::to_string(size.width) + "x" +
                    std::to_string(size.height)
              : ": decoders flip or turn it by 180°") +
         "; the intrinsics must describe the image as decoded, or the image be saved without the "
         "tag)";
}

Eigen::Matrix3d ScaleK(const Eigen::Matrix3d& K, int width, int height, int new_width,
                       int new_height) {
  const double sx = double(new_width) / width, sy = double(new_height) / height;
  Eigen::Matrix3d scaled = K;
  scaled(0, 0) *= sx;
  scaled(0, 1) *= sx;
  scaled(1, 1) *= sy;
  scaled(0, 2) = (K(0, 2) + 0.5) * sx - 0.5;
  scaled(1, 2) = (K(1, 2) + 0.5) * sy - 0.5;
  return scaled;
}

CameraIntrinsics ScaleCamera(const CameraIntrinsics& camera, int width, int height, int new_width,
                             int new_height) {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  K(0, 0) = camera.fx();
  K(1, 1) = camera.fy();
  K(0, 2) = camera.cx();
  K(1, 2) = camera.cy();
  const Eigen::Matrix3d scaled = ScaleK(K, width, height, new_width, new_height);
  CameraIntrinsics out = camera;
  out.width = new_width;
  out.height = new_height;
  out.params[kFx] = scaled(0, 0);
  out.params[kFy] = scaled(1, 1);
  out.params[kCx] = scaled(0, 2);
  out.params[kCy] = scaled(1, 2);
  return out;
}

void RequireRescaledView(int width, int height, const ImageSize& size, const std::string& source,
                         const std::string& image_path) {
  const double sx = double(size.width) / width, sy = double(size.height) / height;
  if (std::abs(sx / sy - 1.0) <= 0.01) return;
  ThrowInput(source, 0,
             "intrinsics are for " + std::to_string(width) + "x" + std::to_string(height) +
                 " pixels but " + image_path + " is " + std::to_string(size.width) + "x" +
                 std::to_string(size.height) +
                 ": another aspect ratio (rotated or cropped), not a rescaled image" +
                 ExifOrientationNote(size));
}

// Images in the recording's image folder that no frame of its files names have no pose and no
// intrinsics, so they cannot take part; a user who sees 23 of 24 images refined must be told why
// (a photo whose metadata file is missing). Only where the frames themselves lie in that folder
// (names without a folder part): elsewhere the folder may hold other things.
static void WarnOfImagesWithoutFrame(const CaptureRecording& recording, Warnings* warnings) {
  std::set<std::string> named;
  for (const CaptureFrame& frame : recording.frames) {
    if (frame.name.find('/') != std::string::npos) return;
    named.insert(frame.name);
  }
  // Images the reader already reported (frames left out of a timestamp join, say).
  for (const Warning& warning : *warnings) {
    named.insert(warning.images.begin(), warning.images.end());
  }
  std::error_code error;
  std::vector<std::string> unnamed;
  for (const auto& entry : fs::directory_iterator(recording.image_root, error)) {
    std::string extension = entry.path().extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file(error) &&
        (extension == ".jpg" || extension == ".jpeg" || extension == ".png") &&
        !named.count(name)) {
      unnamed.push_back(name);
    }
  }
  if (unnamed.empty()) return;
  std::sort(unnamed.begin(), unnamed.end());
  warnings->push_back({"images_without_frame",
                       std::to_string(unnamed.size()) + " image(s) in " + recording.image_root +
                           " have no frame in the " + recording.format +
                           " files (no pose, no intrinsics) and are left out: " + unnamed.front() +
                           (unnamed.size() > 1 ? ", ..." : ""),
                       unnamed,
                       {},
                       {{"folder", recording.image_root}}});
}

Dataset DatasetFromRecording(CaptureRecording recording) {
  Dataset dataset;
  dataset.images.image_root = recording.image_root;
  dataset.files = recording.files;
  dataset.warnings = std::move(recording.warnings);
  PoseSet capture, ground_truth;
  Warning rescaled{"intrinsics_rescaled", "", {}, {}, json::object()};
  for (const CaptureFrame& frame : recording.frames) {
    if (!frame.has_image) {
      ++dataset.num_poses_without_image;
      continue;
    }
    if (!frame.K) ThrowInput(frame.source, 0, "frame " + frame.name + " has no intrinsics");
    const std::string image_path = (fs::path(recording.image_root) / frame.name).string();
    const ImageSize size = ReadImageSize(image_path);
    Eigen::Matrix3d K = *frame.K;
    if (frame.width > 0 && frame.height > 0 &&
        (frame.width != size.width || frame.height != size.height)) {
      RequireRescaledView(frame.width, frame.height, size, frame.source, image_path);
      K = ScaleK(K, frame.width, frame.height, size.width, size.height);
      rescaled.images.push_back(frame.name);
      rescaled.details["from"] = std::to_string(frame.width) + "x" + std::to_string(frame.height);
      rescaled.details["to"] = std::to_string(size.width) + "x" + std::to_string(size.height);
      rescaled.details["file"] = frame.source;
    }
    const CameraIntrinsics camera =
        IntrinsicsFromK(K, size.width, size.height, frame.source, frame.name, &dataset.warnings);
    if (!(camera.cx() >= 0 && camera.cx() <= size.width && camera.cy() >= 0 &&
          camera.cy() <= size.height)) {
      ThrowInput(frame.source, 0,
                 "principal point (" + Short(camera.cx()) + ", " + Short(camera.cy()) +
                     ") lies outside the " + std::to_string(size.width) + "x" +
                     std::to_string(size.height) + " image " + image_path +
                     ": the intrinsics do not belong to this image (rotated? transposed K?)" +
                     ExifOrientationNote(size));
    }
    // Frames with exactly the same intrinsics share a camera (nearly equal ones are merged, with a
    // warning, by LoadDataset).
    const auto same =
        std::find(dataset.images.cameras.begin(), dataset.images.cameras.end(), camera);
    dataset.images.images.push_back({frame.name, size.width, size.height,
                                     static_cast<int>(same - dataset.images.cameras.begin())});
    if (same == dataset.images.cameras.end()) dataset.images.cameras.push_back(camera);
    if (frame.capture) capture.world_from_cam[frame.name] = *frame.capture;
    if (frame.ground_truth) ground_truth.world_from_cam[frame.name] = *frame.ground_truth;
    if (frame.time_s) dataset.timestamps[frame.name] = *frame.time_s;
  }
  WarnOfImagesWithoutFrame(recording, &dataset.warnings);
  if (dataset.images.images.empty()) {
    ThrowInput(recording.image_root, 0,
               "no images: none of the " + std::to_string(recording.frames.size()) + " " +
                   recording.format + " frames has its image in this folder");
  }
  if (!rescaled.images.empty()) {
    rescaled.message = std::to_string(rescaled.images.size()) + " frame(s) have intrinsics for " +
                       rescaled.details["from"].get<std::string>() + " pixels but images of " +
                       rescaled.details["to"].get<std::string>() +
                       ": focal lengths and principal points were rescaled to the images";
    dataset.warnings.push_back(rescaled);
  }
  if (capture.size() > 0) dataset.capture = std::move(capture);
  if (ground_truth.size() > 0) dataset.ground_truth = std::move(ground_truth);
  return dataset;
}

PoseSet PosesOfRecording(const CaptureRecording& recording) {
  PoseSet capture, ground_truth;
  for (const CaptureFrame& frame : recording.frames) {
    if (frame.capture) capture.world_from_cam[frame.name] = *frame.capture;
    if (frame.ground_truth) ground_truth.world_from_cam[frame.name] = *frame.ground_truth;
  }
  return capture.size() > 0 ? capture : ground_truth;
}

}  // namespace raytime

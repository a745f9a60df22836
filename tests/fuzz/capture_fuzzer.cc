// libFuzzer target: the capture and dataset readers that take a folder (formats/record3d.h,
// polycam.h, stray.h, scanner3d.h, nerfcapture.h, mobilebrick.h, scannetpp.h, arkitscenes.h,
// lamar.h), through the two entry points every caller uses: ReadPoseFile (the pose file of
// `prior.format`) and LoadDataset (the dataset stage), whose warnings are then turned into JSON
// text as the stage's summary does. For stray, a dataset that loads is also given decoded video
// frames (AttachVideoFrames), as the dataset stage does after decoding rgb.mp4.
//
// This file is compiled once, into the library capture_fuzz; capture_format_fuzzer.cc is the
// entry point compiled once per format (tests/fuzz/CMakeLists.txt): RAYTIME_CAPTURE_FORMAT is the
// dataset.format, e.g. "record3d", and the target is capture_<name>. (Compiling this file once per
// format took nine 15 s compiles of the sanitizer build.)
//
// Input: a small folder. Each file's bytes follow a line "@@FILE <path>@@" (path relative to the
// capture's root, '/' separated; a path ending in '/' is an empty folder); bytes before the first
// such line are ignored. The multi-byte marker keeps each file mutable on its own (SplitParts).
// Paths that are absolute, contain "..", or collide with a file written before are skipped. For
// stray, a part named "!video" (not written to disk) describes the decoded frames, as whitespace-
// separated integers: count, stride, frames per second, width, height, capture_width (defaults
// 6 1 30 64 48 0).
//
// Besides crashes and escaping exceptions, the target stops on a value that is not finite in what
// a reader returns (a pose, an intrinsic, a timestamp): the readers reject NaN and infinity in
// their files (formats/text_util.h, PoseFromCameraToWorld), so one that appears anyway came
// from arithmetic on valid-looking values (an overflow) and would reach the stages unnoticed.
//
// With RAYTIME_FUZZ_VERBOSE set in the environment (replay executables, when checking that seeds
// load), each step prints what it read or why it rejected the input.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/error.h"
#include "core/warnings.h"
#include "formats/dataset.h"
#include "formats/stray.h"
#include "formats/text_util.h"
#include "tests/fuzz/capture_fuzz.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

namespace fs = std::filesystem;
// The dataset.format of the input being run (set by FuzzCapture; the fuzzers are single-threaded).
const char* current_format = "";
constexpr size_t kMaxFiles = 64;
constexpr size_t kMaxPathBytes = 200;

bool Verbose() {
  static const bool verbose = std::getenv("RAYTIME_FUZZ_VERBOSE") != nullptr;
  return verbose;
}

void Report(const char* step, const char* what) {
  if (Verbose()) std::fprintf(stderr, "  %s %s: %s\n", current_format, step, what);
}

[[noreturn]] void NotFinite(const std::string& what) {
  std::fprintf(stderr, "%s reader returned a value that is not finite: %s\n", current_format,
               what.c_str());
  std::abort();
}

void RequireFinite(const raytime::PoseSet& poses, const char* set) {
  for (const auto& [name, pose] : poses.world_from_cam) {
    if (!pose.rotation.coeffs().allFinite() || !pose.translation.allFinite()) {
      NotFinite(std::string(set) + " pose of " + name);
    }
  }
}

void RequireFinite(const raytime::Dataset& dataset) {
  for (const raytime::CameraIntrinsics& camera : dataset.images.cameras) {
    for (const double value : camera.params) {
      if (!std::isfinite(value)) NotFinite("camera intrinsics");
    }
  }
  if (dataset.capture) RequireFinite(*dataset.capture, "capture");
  if (dataset.ground_truth) RequireFinite(*dataset.ground_truth, "ground truth");
  for (const auto& [name, time] : dataset.timestamps) {
    if (!std::isfinite(time)) NotFinite("timestamp of " + name);
  }
}

// A relative path that stays inside the root: no leading '/', no ".." component, no NUL.
bool SafeRelativePath(std::string_view path) {
  if (path.empty() || path.size() > kMaxPathBytes || path.front() == '/' ||
      path.find('\0') != std::string_view::npos) {
    return false;
  }
  for (const std::string_view part : raytime::fuzz::SplitParts(path, "/")) {
    if (part == "..") return false;
  }
  return true;
}

// Writes the folder an input describes below `root`; returns the "!video" part.
std::string_view WriteTree(std::string_view input, const std::string& root) {
  std::string_view video;
  const auto parts = raytime::fuzz::SplitParts(input, "@@FILE ");
  for (size_t i = 1; i < parts.size() && i <= kMaxFiles; ++i) {
    const size_t end = parts[i].find("@@\n");
    if (end == std::string_view::npos) continue;
    const std::string_view path = parts[i].substr(0, end);
    const std::string_view bytes = parts[i].substr(end + 3);
    if (path == "!video") {
      video = bytes;
      continue;
    }
    if (!SafeRelativePath(path)) continue;
    const fs::path target = fs::path(root) / std::string(path);
    std::error_code error;
    if (path.back() == '/') {
      fs::create_directories(target, error);
      continue;
    }
    fs::create_directories(target.parent_path(), error);
    if (error || fs::exists(target, error)) continue;  // a parent is a file, or written before
    std::ofstream out(target, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  return video;
}

// Decoded frames as ExtractVideoFrames reports them: frame_NNNNNN.jpg for every stride-th frame,
// one camera of the decoded size, presentation time = frame number / fps.
void AttachDecodedFrames(std::string_view description, raytime::Dataset* dataset) {
  using namespace raytime;
  int values[6] = {6, 1, 30, 64, 48, 0};
  const auto tokens = text::SplitWhitespace(description);
  for (size_t i = 0; i < tokens.size() && i < 6; ++i) {
    int value = 0;  // from_chars writes a leading number even when the token has more after it
    if (text::ParseInt(tokens[i], &value)) values[i] = value;
  }
  const int count = std::clamp(values[0], 1, 64), stride = std::clamp(values[1], 1, 1000);
  const int fps = std::clamp(values[2], 1, 240);
  const int width = std::clamp(values[3], 1, 8192), height = std::clamp(values[4], 1, 8192);
  const int capture_width = std::clamp(values[5], 0, 16384);
  ImageSet frames;
  frames.image_root = fuzz::ScratchPath("dataset_frames");
  CameraIntrinsics camera;
  camera.width = width;
  camera.height = height;
  frames.cameras.push_back(camera);
  std::vector<DecodedFrame> decoded;
  for (int k = 0; k < count; ++k) {
    const int number = k * stride;
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%06d.jpg", number);
    frames.images.push_back({name, width, height, 0});
    decoded.push_back({number, double(number) / fps});
  }
  AttachVideoFrames(frames, decoded, capture_width, TimestampJoinOptions(), dataset);
}

}  // namespace

int raytime::fuzz::FuzzCapture(const char* format, const uint8_t* data, size_t size) {
  using namespace raytime;
  current_format = format;
  fuzz::ClearScratch();
  const std::string root = fuzz::ScratchPath("capture");
  std::filesystem::create_directory(root);
  const std::string_view video =
      WriteTree(std::string_view(reinterpret_cast<const char*>(data), size), root);
  const bool stray = std::string_view(current_format) == "stray";
  bool poses_read = false;
  try {
    const PoseSet poses = ReadPoseFile(current_format, root);
    poses_read = true;
    RequireFinite(poses, "pose file");
    Report("pose file", (std::to_string(poses.size()) + " poses").c_str());
  } catch (const InputError& e) {
    Report("pose file", e.what());
  }
  // Every format but stray parses the same files the same way for both: a reader that rejected
  // them for the pose file rejects them for the dataset too.
  if (!poses_read && !stray) return 0;
  try {
    DatasetOptions options;
    options.format = current_format;
    options.root = root;
    Dataset dataset = LoadDataset(options);
    if (dataset.video) AttachDecodedFrames(video, &dataset);
    RequireFinite(dataset);
    // The dataset stage's summary holds the warnings; summary.json must be writable.
    const std::string warnings = WarningsToJson(dataset.warnings).dump();
    Report("dataset",
           (std::to_string(dataset.images.images.size()) + " images, " +
            std::to_string(dataset.images.cameras.size()) + " cameras, capture " +
            std::to_string(dataset.capture ? dataset.capture->size() : 0) + ", ground truth " +
            std::to_string(dataset.ground_truth ? dataset.ground_truth->size() : 0) +
            ", warnings " + warnings)
               .c_str());
  } catch (const InputError& e) {
    Report("dataset", e.what());
  }
  return 0;
}

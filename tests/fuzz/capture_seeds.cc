// Writes the seed corpus of the capture_* fuzz targets (capture_fuzzer.cc) and npz: a fixture of
// each format written by the test-only writers (tests/capture_fixtures.h) and packed into the
// targets' input form ("@@FILE <path>@@" before each file's bytes).
//
//   ninja -C build-dev capture_fuzz_seeds && build-dev/tests/fuzz/capture_fuzz_seeds
//   tests/fuzz/corpus
//
// The frames are the first three of fixtures::SampleCapture() (the sample scene's ground truth,
// perturbed; per-frame intrinsics and times), with each image replaced by a JPEG header of the
// same size (768x512): the readers only read image headers, and a seed should be small. Only the
// stray fixture encodes the sample images into rgb.mp4 (the writer needs pixels); its video is
// then replaced by a placeholder, since no reader decodes it, and a "!video" part describes the
// decoded frames instead.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/capture_fixtures.h"

namespace fs = std::filesystem;
using namespace raytime;

namespace {

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

std::string Big16(int value) {
  return {static_cast<char>((value >> 8) & 0xFF), static_cast<char>(value & 0xFF)};
}

// The smallest JPEG whose size ReadImageSize reads: SOI, a JFIF APP0, a baseline SOF0 of three
// components, EOI. `orientation` > 0 adds an EXIF APP1 (big-endian TIFF) with that orientation.
std::string JpegHeader(int width, int height, int orientation = 0) {
  std::string jpeg = "\xFF\xD8";
  jpeg += std::string("\xFF\xE0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00", 18);
  if (orientation > 0) {
    std::string exif("Exif\0\0MM\0\x2a\0\0\0\x08", 14);
    exif += std::string("\x00\x01\x01\x12\x00\x03\x00\x00\x00\x01", 10) + Big16(orientation) +
            std::string("\0\0\0\0\0\0", 6);
    jpeg += "\xFF\xE1" + Big16(static_cast<int>(exif.size()) + 2) + exif;
  }
  jpeg += std::string("\xFF\xC0\x00\x11\x08", 5) + Big16(height) + Big16(width) +
          std::string("\x03\x01\x22\x00\x02\x11\x01\x03\x11\x01", 10);
  jpeg += "\xFF\xD9";
  return jpeg;
}

// The signature and IHDR chunk of a PNG (what ReadImageSize reads).
std::string PngHeader(int width, int height) {
  const auto big32 = [](int v) { return Big16(v >> 16) + Big16(v & 0xFFFF); };
  return std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16) + big32(width) + big32(height) +
         std::string("\x08\x02\0\0\0\0\0\0\0", 9);
}

// Every file below `root` as the targets' input, in path order.
std::string Pack(const fs::path& root) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(root)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  std::string input;
  for (const fs::path& file : files) {
    input += "@@FILE " + file.lexically_relative(root).generic_string() + "@@\n" + ReadBytes(file);
  }
  return input;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_FOLDER (tests/fuzz/corpus)\n", argv[0]);
    return 2;
  }
  const fs::path corpus = argv[1];
  const fs::path work = fs::temp_directory_path() / "raytime_capture_seeds";
  fs::remove_all(work);

  fixtures::Capture full = fixtures::SampleCapture();
  fixtures::Capture capture = full;
  capture.frames.resize(3);
  full.frames.resize(3);
  WriteBytes(work / "images/header.jpg", JpegHeader(capture.width, capture.height));
  for (fixtures::Frame& frame : capture.frames) frame.image = (work / "images/header.jpg").string();

  const Rigid3 arkit_from_world(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(0.5, -0.25, 1.0));
  const Rigid3 rig_from_cam(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY())),
                            Eigen::Vector3d(0.01, 0.02, 0.0));
  const auto seed = [&](const std::string& target, const std::string& name,
                        const std::function<void(const fs::path&)>& write) {
    const fs::path root = work / target / name;
    write(root);
    WriteBytes(corpus / target / name, Pack(root));
  };

  seed("capture_record3d", "fixture",
       [&](const fs::path& root) { fixtures::WriteRecord3d(capture, root.string()); });
  // Metadata for images twice the size (intrinsics_rescaled); frame 1 a PNG, frame 2 a JPEG with
  // an EXIF orientation (3: turned half round, same size).
  seed("capture_record3d", "rescaled-png-exif", [&](const fs::path& root) {
    fixtures::WriteRecord3d(capture, root.string(), 2.0);
    fs::remove(root / "rgb/1.jpg");
    WriteBytes(root / "rgb/1.png", PngHeader(capture.width, capture.height));
    WriteBytes(root / "rgb/2.jpg", JpegHeader(capture.width, capture.height, 3));
  });
  seed("capture_polycam", "fixture",
       [&](const fs::path& root) { fixtures::WritePolycam(capture, root.string()); });
  // Only the raw ARKit cameras (no corrected_*), one without its image.
  seed("capture_polycam", "raw-only", [&](const fs::path& root) {
    fixtures::WritePolycam(capture, root.string());
    fs::remove_all(root / "keyframes/corrected_images");
    fs::remove_all(root / "keyframes/corrected_cameras");
    fs::remove(fs::directory_iterator(root / "keyframes/images")->path());
  });
  seed("capture_scanner3d", "fixture",
       [&](const fs::path& root) { fixtures::WriteScanner3d(capture, root.string()); });
  seed("capture_nerfcapture", "fixture",
       [&](const fs::path& root) { fixtures::WriteNerfCapture(capture, root.string()); });
  // The app's own layout: images/<n>.png named "images/<n>" in transforms.json.
  seed("capture_nerfcapture", "png", [&](const fs::path& root) {
    fixtures::WriteNerfCapture(capture, root.string());
    for (int i = 0; i < 3; ++i) {
      fs::remove(root / ("images/" + std::to_string(i) + ".jpg"));
      WriteBytes(root / ("images/" + std::to_string(i) + ".png"),
                 PngHeader(capture.width, capture.height));
    }
  });
  seed("capture_mobilebrick", "fixture",
       [&](const fs::path& root) { fixtures::WriteMobileBrick(capture, root.string()); });
  seed("capture_mobilebrick", "arkit-npz", [&](const fs::path& root) {
    fixtures::WriteMobileBrick(capture, root.string(), &arkit_from_world);
    WriteBytes(corpus / "npz" / "cameras_arkit.npz", ReadBytes(root / "cameras_arkit.npz"));
  });
  seed("capture_scannetpp", "opencv-axes", [&](const fs::path& root) {
    fixtures::WriteScanNetPP(capture, root.string(), arkit_from_world, false);
  });
  seed("capture_scannetpp", "arkit-axes", [&](const fs::path& root) {
    fixtures::WriteScanNetPP(capture, root.string(), arkit_from_world, true);
  });
  seed("capture_arkitscenes", "fixture", [&](const fs::path& root) {
    fixtures::WriteArkitScenes(capture, root.string(), "41069021");
  });
  // The 3DOD layout: everything in <video>_frames/ (the target's root folder is "capture").
  seed("capture_arkitscenes", "3dod-layout", [&](const fs::path& root) {
    fixtures::WriteArkitScenes(capture, (root / "capture_frames").string(), "41069021");
  });
  seed("capture_lamar", "fixture", [&](const fs::path& root) {
    fixtures::WriteLamar(capture, root.string(), arkit_from_world, rig_from_cam);
  });
  seed("capture_stray", "fixture", [&](const fs::path& root) {
    std::vector<fixtures::OdometryRow> rows;
    if (!fixtures::WriteStray(full, root.string(), 10.0, 30.0, 1.0, &rows)) {
      throw std::runtime_error("this OpenCV cannot write MPEG-4 video");
    }
    WriteBytes(root / "rgb.mp4", "not decoded by the readers\n");
    WriteBytes(root / "!video", "3 1 10 768 512 0\n");
  });
  fs::remove_all(work);
  return 0;
}

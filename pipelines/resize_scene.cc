#include "pipelines/resize_scene.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/strecha.h"
#include "frontend/image_reading.h"

namespace fs = std::filesystem;

namespace raytime {

int ResizeScene(const DatasetOptions& input, const std::string& output_root,
                const ResizeSceneOptions& options) {
  const Dataset dataset = LoadDataset(input);
  if (!dataset.ground_truth) ThrowInput(input.root, 0, "the dataset has no poses to carry over");
  if (options.width <= 0) throw InputError("--width must be positive");
  WriteDirectoryAtomically(output_root, [&](const std::string& dir) {
    fs::create_directories(fs::path(dir) / "images");
    fs::create_directories(fs::path(dir) / "gt_dense_cameras");
    for (const auto& image : dataset.images.images) {
      const std::string source = (fs::path(dataset.images.image_root) / image.name).string();
      const cv::Mat pixels = ReadImage(source, cv::IMREAD_COLOR);
      const double scale = static_cast<double>(options.width) / pixels.cols;
      const int height = static_cast<int>(std::lround(pixels.rows * scale));
      cv::Mat resized;
      cv::resize(pixels, resized, cv::Size(options.width, height), 0, 0, cv::INTER_AREA);
      cv::imwrite((fs::path(dir) / "images" / image.name).string(), resized,
                  {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality});

      // Pixel centres sit at integers (OpenCV): a pixel edge at -0.5 maps to -0.5, so
      // c' = s (c + 0.5) - 0.5, with separate x and y factors after rounding the height.
      const double sx = static_cast<double>(options.width) / pixels.cols;
      const double sy = static_cast<double>(height) / pixels.rows;
      StrechaCamera camera;
      camera.intrinsics = dataset.images.cameras[image.camera_index];
      camera.intrinsics.width = options.width;
      camera.intrinsics.height = height;
      camera.intrinsics.params[kFx] *= sx;
      camera.intrinsics.params[kFy] *= sy;
      camera.intrinsics.params[kCx] = sx * (camera.intrinsics.params[kCx] + 0.5) - 0.5;
      camera.intrinsics.params[kCy] = sy * (camera.intrinsics.params[kCy] + 0.5) - 0.5;
      camera.world_from_cam = dataset.ground_truth->world_from_cam.at(image.name);
      WriteStrechaCamera((fs::path(dir) / "gt_dense_cameras" / (image.name + ".camera")).string(),
                         camera);
      spdlog::info(fmt::format("resize: {} {}x{} -> {}x{}", image.name, pixels.cols, pixels.rows,
                               options.width, height));
    }
  });
  return static_cast<int>(dataset.images.images.size());
}

}  // namespace raytime

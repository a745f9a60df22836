#include "splat/held_out_render.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "core/error.h"
#include "formats/colmap_model.h"

namespace fs = std::filesystem;

namespace raytime {

std::vector<std::string> HeldOutNames(const std::string& data_dir) {
  const fs::path path = fs::path(data_dir) / "test.txt";
  std::ifstream in(path);
  if (!in) ThrowInput(path.string(), 0, "no held-out list (the 3dgs export writes test.txt)");
  std::vector<std::string> names;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty()) names.push_back(line);
  }
  return names;
}

namespace {

// `count` points uniform in the ball around the cameras of `model` (see WriteTrainOnlyView), with
// random colours; no tracks (a trainer reads positions and colours only).
std::map<uint64_t, ColmapPoint3D> RandomBallPoints(const ColmapModel& model, int count, int seed) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> centres;
  for (const auto& [id, image] : model.images) {
    centres.push_back(image.cam_from_world.Inverse().translation);
    centre += centres.back();
  }
  centre /= static_cast<double>(centres.size());
  double spread = 0.0;
  for (const Eigen::Vector3d& c : centres) spread = std::max(spread, (c - centre).norm());
  const double radius = 3.0 * std::max(spread, 1e-6);
  std::mt19937 random(static_cast<uint32_t>(seed) * 2654435761u + 1u);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform;
  std::uniform_int_distribution<int> colour(0, 255);
  std::map<uint64_t, ColmapPoint3D> points;
  for (int k = 0; k < count; ++k) {
    ColmapPoint3D point;
    point.point3D_id = static_cast<uint64_t>(k) + 1;
    Eigen::Vector3d direction(normal(random), normal(random), normal(random));
    direction.normalize();
    point.xyz = centre + radius * std::cbrt(uniform(random)) * direction;
    for (int c = 0; c < 3; ++c) point.rgb[c] = static_cast<uint8_t>(colour(random));
    points[point.point3D_id] = point;
  }
  return points;
}

// Gives the items of `items` (keyed by their own id, the member `id`) their ids in a shuffled
// order drawn from `seed`, so the map (and a file written from it) lists them in that order.
// Returns old id -> new id, for the references elsewhere to follow.
template <class Id, class Item>
std::map<Id, Id> ShuffleIds(std::map<Id, Item>* items, Id Item::*id, uint32_t seed) {
  std::vector<Id> ids;
  for (const auto& [key, item] : *items) ids.push_back(key);
  std::vector<Id> shuffled = ids;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(seed));
  std::map<Id, Id> new_id;
  for (size_t k = 0; k < ids.size(); ++k) new_id[ids[k]] = shuffled[k];
  std::map<Id, Item> renumbered;
  for (auto& [key, item] : *items) {
    item.*id = new_id.at(key);
    renumbered[item.*id] = std::move(item);
  }
  *items = std::move(renumbered);
  return new_id;
}

}  // namespace

int WriteTrainOnlyView(const std::string& data_dir, const std::string& view_dir, int seed,
                       int random_points) {
  const std::vector<std::string> held_out = HeldOutNames(data_dir);
  const std::set<std::string> test(held_out.begin(), held_out.end());
  ColmapModel model = ReadColmapModel((fs::path(data_dir) / "sparse" / "0").string());
  for (auto it = model.images.begin(); it != model.images.end();) {
    it = test.count(it->second.name) ? model.images.erase(it) : std::next(it);
  }
  if (model.images.empty()) {
    ThrowInput((fs::path(data_dir) / "train.txt").string(), 0,
               "the export holds no training image: nothing to train on");
  }
  if (seed != 0) {
    const std::map<uint32_t, uint32_t> new_id =
        ShuffleIds(&model.images, &ColmapImage::image_id, static_cast<uint32_t>(seed));
    for (auto& [id, point] : model.points3D) {
      for (ColmapTrackElement& element : point.track) {
        const auto it = new_id.find(element.image_id);
        if (it != new_id.end()) element.image_id = it->second;
      }
    }
  }
  if (random_points > 0) {
    model.points3D = RandomBallPoints(model, random_points, seed);
    for (auto& [id, image] : model.images) {
      std::fill(image.point3D_ids.begin(), image.point3D_ids.end(), kInvalidPoint3DId);
    }
  }
  if (seed != 0) {
    // The points' file order too: a trainer that draws each Gaussian's random state in file order
    // from a fixed seed (OpenSplat's initial rotations, torch seeded with 42) then gives every
    // point another draw.
    const std::map<uint64_t, uint64_t> new_id =
        ShuffleIds(&model.points3D, &ColmapPoint3D::point3D_id, static_cast<uint32_t>(seed) + 1u);
    for (auto& [id, image] : model.images) {
      for (uint64_t& point_id : image.point3D_ids) {
        const auto it = new_id.find(point_id);
        if (it != new_id.end()) point_id = it->second;
      }
    }
  }
  const fs::path sparse = fs::path(view_dir) / "sparse" / "0";
  fs::create_directories(sparse);
  WriteColmapModelBinary(model, sparse.string());
  return static_cast<int>(model.images.size());
}

HeldOutScore RenderAndScoreHeldOutViews(const GaussianSplats& splats, const std::string& data_dir,
                                        const std::string& out_dir,
                                        const HeldOutRenderOptions& options) {
  if (!(options.downscale >= 1.0)) {
    throw std::invalid_argument("RenderAndScoreHeldOutViews: downscale below 1");
  }
  const fs::path model_dir = fs::path(data_dir) / "sparse" / "0";
  const ColmapModel model = ReadColmapModel(model_dir.string());
  ImageSet images;
  PoseSet poses;
  FromColmapModel(model, &images, &poses);
  const fs::path renders = fs::path(out_dir) / "renders", gt = fs::path(out_dir) / "gt";
  fs::create_directories(renders);
  fs::create_directories(gt);
  std::vector<HeldOutView> views;
  for (const std::string& name : HeldOutNames(data_dir)) {
    const int index = images.Find(name);
    if (index < 0 || !poses.Has(name)) {
      ThrowInput(model_dir.string(), 0, "held-out image '" + name + "' (test.txt) has no camera");
    }
    const fs::path photo_path = fs::path(data_dir) / "images" / name;
    const cv::Mat photo = cv::imread(photo_path.string(), cv::IMREAD_COLOR);
    if (photo.empty()) ThrowInput(photo_path.string(), 0, "cannot read the held-out photo");
    CameraIntrinsics camera = images.cameras.at(images.images[index].camera_index);
    const double d = options.downscale;
    const int width = static_cast<int>(std::floor(photo.cols / d));
    const int height = static_cast<int>(std::floor(photo.rows / d));
    // The pixel grid shrinks about the top-left corner: in the OpenCV convention a centre at c
    // moves to (c + 0.5) / d − 0.5.
    camera.params[kFx] /= d;
    camera.params[kFy] /= d;
    camera.params[kCx] = (camera.params[kCx] + 0.5) / d - 0.5;
    camera.params[kCy] = (camera.params[kCy] + 0.5) / d - 0.5;
    camera.width = width;
    camera.height = height;
    cv::Mat reference = photo;
    if (width != photo.cols || height != photo.rows) {
      cv::resize(photo, reference, cv::Size(width, height), 0, 0, cv::INTER_AREA);
    }
    const cv::Mat render =
        RenderGaussianSplats(splats, camera, poses.world_from_cam.at(name), options.render);
    cv::Mat render8;
    render.convertTo(render8, CV_8UC3, 255.0);
    // One flat file per image, even for names in subfolders ("rgb/1.jpg" -> "rgb_1.png").
    std::string stem = fs::path(name).replace_extension(".png").generic_string();
    std::replace(stem.begin(), stem.end(), '/', '_');
    if (!cv::imwrite((renders / stem).string(), render8) ||
        !cv::imwrite((gt / stem).string(), reference)) {
      ThrowInput(out_dir, 0, "cannot write the held-out renders");
    }
    views.push_back({(renders / stem).string(), (gt / stem).string()});
  }
  if (views.empty()) ThrowInput((fs::path(data_dir) / "test.txt").string(), 0, "no held-out image");
  return ScoreHeldOutViews(views);
}

}  // namespace raytime

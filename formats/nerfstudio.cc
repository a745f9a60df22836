#include "formats/nerfstudio.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

#include "core/atomic_file.h"
#include "core/error.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

namespace {

// OpenCV camera axes (x right, y down, z forward) -> OpenGL (x right, y up, z backwards); the
// matrix is its own inverse.
const Eigen::Matrix3d kFlipYZ = Eigen::Vector3d(1, -1, -1).asDiagonal();

class FrameContext {
 public:
  FrameContext(const std::string& path, const json& top, const json& frame, size_t index)
      : path_(path), top_(top), frame_(frame), index_(index) {}

  [[noreturn]] void Fail(const std::string& message) const {
    std::string frame = "frame " + std::to_string(index_);
    if (frame_.contains("file_path") && frame_["file_path"].is_string()) {
      frame += " (" + frame_["file_path"].get<std::string>() + ")";
    }
    ThrowInput(path_, 0, frame + ": " + message);
  }
  // A frame's own value (transform_matrix, file_path), else the top level's.
  const json* Find(const char* key) const {
    if (frame_.contains(key)) return &frame_[key];
    if (top_.contains(key)) return &top_[key];
    return nullptr;
  }
  // An intrinsic as nerfstudio's dataparser reads it: the top level's value when it has one
  // (then every frame shares it and a frame's own is ignored), else the frame's. Distortion is one
  // group: when the top level names any of it (k1, k2, k3, k4, p1, p2 or distortion_params) all of
  // it comes from there, missing terms 0.
  const json* FindIntrinsic(const char* key) const {
    const bool distortion = IsDistortionKey(key);
    const json& source = (distortion ? NamesDistortion(top_) : top_.contains(key)) ? top_ : frame_;
    if (distortion && source.contains("distortion_params")) return DistortionTerm(source, key);
    return source.contains(key) ? &source[key] : nullptr;
  }
  double Number(const char* key, double fallback) const {
    return NumberOf(key, FindIntrinsic(key), fallback);
  }
  double RequiredNumber(const char* key) const {
    if (!FindIntrinsic(key)) {
      Fail(std::string("missing ") + key + " (neither in the frame nor shared)");
    }
    return Number(key, 0.0);
  }
  int Size(const char* key) const {
    const double value = RequiredNumber(key);
    if (value < 1 || value != std::floor(value) || value > 1e9) {
      Fail(std::string(key) + " must be a positive whole number of pixels, got " +
           FindIntrinsic(key)->dump());
    }
    return static_cast<int>(value);
  }

 private:
  // nerfstudio's distortion_params order (camera_utils.get_distortion_params).
  static constexpr const char* kDistortionOrder[6] = {"k1", "k2", "k3", "k4", "p1", "p2"};

  static bool IsDistortionKey(const char* key) {
    for (const char* name : kDistortionOrder) {
      if (std::string(key) == name) return true;
    }
    return false;
  }
  static bool NamesDistortion(const json& object) {
    if (object.contains("distortion_params")) return true;
    for (const char* name : kDistortionOrder) {
      if (object.contains(name)) return true;
    }
    return false;
  }
  // The term `key` of `source`'s distortion_params: [k1, k2, k3, k4, p1, p2].
  const json* DistortionTerm(const json& source, const char* key) const {
    const json& params = source["distortion_params"];
    if (!params.is_array() || params.size() != 6) {
      Fail("distortion_params must be [k1, k2, k3, k4, p1, p2], got " + params.dump());
    }
    for (size_t i = 0; i < 6; ++i) {
      if (std::string(key) == kDistortionOrder[i]) return &params[i];
    }
    return nullptr;
  }
  double NumberOf(const char* key, const json* value, double fallback) const {
    if (!value) return fallback;
    if (!value->is_number()) Fail(std::string(key) + " must be a number, got " + value->dump());
    const double number = value->get<double>();
    if (!std::isfinite(number)) Fail(std::string(key) + " must be finite");
    return number;
  }

  const std::string& path_;
  const json& top_;
  const json& frame_;
  size_t index_;
};

CameraIntrinsics ReadIntrinsics(const FrameContext& frame) {
  if (const json* model = frame.Find("camera_model")) {
    const std::string name = model->is_string() ? model->get<std::string>() : model->dump();
    if (name != "OPENCV" && name != "PINHOLE" && name != "SIMPLE_PINHOLE") {
      frame.Fail("camera_model " + name + " is not supported (OPENCV, PINHOLE, SIMPLE_PINHOLE)");
    }
  }
  for (const char* key : {"k3", "k4"}) {
    if (frame.Number(key, 0.0) != 0.0) {
      frame.Fail(std::string(key) + " is not supported (raytime models k1, k2, p1, p2)");
    }
  }
  CameraIntrinsics intrinsics;
  intrinsics.width = frame.Size("w");
  intrinsics.height = frame.Size("h");
  // instant-ngp files may give only the field of view.
  const auto focal_from_angle = [&](const char* angle_key, int size, double fallback) {
    const double angle = frame.Number(angle_key, 0.0);
    return angle > 0 ? 0.5 * size / std::tan(0.5 * angle) : fallback;
  };
  double fx = frame.Number("fl_x", focal_from_angle("camera_angle_x", intrinsics.width, 0.0));
  if (!(fx > 0)) frame.Fail("missing or non-positive fl_x (and no camera_angle_x)");
  double fy = frame.Number("fl_y", focal_from_angle("camera_angle_y", intrinsics.height, fx));
  if (!(fy > 0)) frame.Fail("fl_y must be positive");
  // Defaults are the image centre in nerfstudio's (COLMAP's) pixel convention.
  const double cx = frame.Number("cx", 0.5 * intrinsics.width);
  const double cy = frame.Number("cy", 0.5 * intrinsics.height);
  intrinsics.params = {fx,
                       fy,
                       cx - 0.5,
                       cy - 0.5,
                       frame.Number("k1", 0.0),
                       frame.Number("k2", 0.0),
                       frame.Number("p1", 0.0),
                       frame.Number("p2", 0.0)};
  return intrinsics;
}

Rigid3 ReadWorldFromCam(const FrameContext& frame) {
  const json* matrix = frame.Find("transform_matrix");
  if (!matrix) frame.Fail("missing transform_matrix");
  std::string shape = "not an array of rows";
  if (matrix->is_array() && !matrix->empty()) {
    const bool rows_agree = std::all_of(matrix->begin(), matrix->end(), [&](const json& row) {
      return row.is_array() && row.size() == matrix->front().size();
    });
    shape = rows_agree
                ? std::to_string(matrix->size()) + "x" + std::to_string(matrix->front().size())
                : std::to_string(matrix->size()) + " rows of unequal length";
  }
  if (shape != "4x4") frame.Fail("transform_matrix must be 4x4, got " + shape);
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      const json& value = (*matrix)[r][c];
      if (!value.is_number() || !std::isfinite(value.get<double>())) {
        frame.Fail("transform_matrix[" + std::to_string(r) + "][" + std::to_string(c) +
                   "] is not a finite number: " + value.dump());
      }
      m(r, c) = value.get<double>();
    }
  }
  if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9) {
    frame.Fail("transform_matrix last row must be 0 0 0 1");
  }
  const Eigen::Matrix3d world_from_gl = m.topLeftCorner<3, 3>();
  const std::string problem = RotationMatrixProblem(world_from_gl);
  if (!problem.empty()) frame.Fail("transform_matrix: " + problem);
  return Rigid3(Eigen::Quaterniond(Orthonormalize(world_from_gl) * kFlipYZ),
                m.topRightCorner<3, 1>());
}

// The directory shared by every path ("images/" for "images/a.jpg", "images/b.jpg"), including
// its trailing slash; "" when there is none.
std::string CommonDirectory(const std::vector<std::string>& paths) {
  std::string common = paths.front().substr(0, paths.front().rfind('/') + 1);
  for (const std::string& path : paths) {
    while (!common.empty() && path.compare(0, common.size(), common) != 0) {
      common.pop_back();
      common.erase(common.rfind('/') + 1);
    }
  }
  return common;
}

}  // namespace

json TransformsIntrinsicsJson(const CameraIntrinsics& intrinsics) {
  const auto& p = intrinsics.params;
  return {{"w", intrinsics.width}, {"h", intrinsics.height}, {"fl_x", p[kFx]},
          {"fl_y", p[kFy]},        {"cx", p[kCx] + 0.5},     {"cy", p[kCy] + 0.5},
          {"k1", p[kK1]},          {"k2", p[kK2]},           {"p1", p[kP1]},
          {"p2", p[kP2]}};
}

json ParseTransformsJson(const std::string& path, const std::string& text) {
  json top;
  try {
    top = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number like 1e999
    ThrowInput(path, 0, std::string("not valid JSON: ") + e.what());
  }
  if (!top.is_object()) ThrowInput(path, 0, "expected a JSON object with a \"frames\" array");
  if (!top.contains("frames") || !top["frames"].is_array() || top["frames"].empty()) {
    ThrowInput(path, 0, "expected a non-empty \"frames\" array");
  }
  return top;
}

TransformsFrames ReadTransformsFrames(const std::string& path, const json& top) {
  const json& frames = top["frames"];
  std::vector<std::string> file_paths;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameContext frame(path, top, frames[i], i);
    if (!frames[i].is_object()) frame.Fail("expected an object");
    const json* file_path = frames[i].contains("file_path") ? &frames[i]["file_path"] : nullptr;
    if (!file_path || !file_path->is_string() || file_path->get<std::string>().empty()) {
      frame.Fail("missing file_path (a non-empty string)");
    }
    std::string name = file_path->get<std::string>();
    if (name.compare(0, 2, "./") == 0) name.erase(0, 2);
    file_paths.push_back(name);
  }
  TransformsFrames result;
  result.common_directory = CommonDirectory(file_paths);
  std::set<std::string> names;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameContext frame(path, top, frames[i], i);
    const std::string name = file_paths[i].substr(result.common_directory.size());
    if (name.empty()) frame.Fail("file_path names a directory");
    if (!names.insert(name).second) frame.Fail("image " + name + " appears in more than one frame");
    result.frames.push_back({name, ReadIntrinsics(frame), ReadWorldFromCam(frame)});
  }
  return result;
}

void ReadTransformsJson(const std::string& path, ImageSet* images, PoseSet* poses,
                        std::string* text) {
  const std::string read = ReadTextFile(path);
  const json top = ParseTransformsJson(path, read);
  const TransformsFrames parsed = ReadTransformsFrames(path, top);
  ImageSet image_set;
  PoseSet pose_set;
  for (const TransformsFrame& frame : parsed.frames) {
    const auto same = std::find(image_set.cameras.begin(), image_set.cameras.end(), frame.camera);
    const int camera_index = static_cast<int>(same - image_set.cameras.begin());
    if (same == image_set.cameras.end()) image_set.cameras.push_back(frame.camera);
    pose_set.world_from_cam.emplace(frame.name, frame.world_from_cam);
    image_set.images.push_back({frame.name, frame.camera.width, frame.camera.height, camera_index});
  }
  std::sort(image_set.images.begin(), image_set.images.end(),
            [](const ImageInfo& a, const ImageInfo& b) { return a.name < b.name; });
  std::string root =
      (fs::path(path).parent_path() / parsed.common_directory).lexically_normal().string();
  while (root.size() > 1 && root.back() == '/') root.pop_back();
  image_set.image_root = root;
  if (images) *images = std::move(image_set);
  if (poses) *poses = std::move(pose_set);
  if (text) *text = read;
}

json TransformMatrixJson(const Rigid3& world_from_cam) {
  const Eigen::Matrix3d world_from_gl =
      world_from_cam.rotation.normalized().toRotationMatrix() * kFlipYZ;
  json matrix = json::array();
  for (int r = 0; r < 3; ++r) {
    matrix.push_back({world_from_gl(r, 0), world_from_gl(r, 1), world_from_gl(r, 2),
                      world_from_cam.translation[r]});
  }
  matrix.push_back({0.0, 0.0, 0.0, 1.0});
  return matrix;
}

void WriteTransformsJson(const std::string& path, const ImageSet& images, const PoseSet& poses,
                         const std::string& image_prefix, const json& extra_fields,
                         const json& frame_fields) {
  const NameJoin join = JoinNames(Names(images), Names(poses));
  if (!join.only_right.empty()) {
    throw InputError("poses without an image: " + join.Describe("images", "poses"));
  }
  std::vector<const ImageInfo*> posed;
  for (const ImageInfo& image : images.images) {
    if (!poses.Has(image.name)) continue;
    if (image.camera_index < 0 || size_t(image.camera_index) >= images.cameras.size()) {
      throw std::invalid_argument("image " + image.name + " has camera index " +
                                  std::to_string(image.camera_index) + " out of range");
    }
    posed.push_back(&image);
  }
  const bool shared = std::all_of(posed.begin(), posed.end(), [&](const ImageInfo* image) {
    return images.cameras[image->camera_index] == images.cameras[posed.front()->camera_index];
  });

  json top = shared && !posed.empty()
                 ? TransformsIntrinsicsJson(images.cameras[posed.front()->camera_index])
                 : json::object();
  top["camera_model"] = "OPENCV";
  json frames = json::array();
  for (const ImageInfo* image : posed) {
    json frame =
        shared ? json::object() : TransformsIntrinsicsJson(images.cameras[image->camera_index]);
    frame["file_path"] = image_prefix + image->name;
    frame["transform_matrix"] = TransformMatrixJson(poses.world_from_cam.at(image->name));
    const auto fields = frame_fields.find(image->name);
    if (fields != frame_fields.end()) {
      for (const auto& [key, value] : fields->items()) frame[key] = value;
    }
    frames.push_back(frame);
  }
  top["frames"] = frames;
  for (const auto& [key, value] : extra_fields.items()) top[key] = value;
  WriteTextFileAtomically(path, top.dump(2) + "\n");
}

}  // namespace raytime

#include "formats/colmap_model.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <type_traits>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

// COLMAP 3.8's camera models: the position in this table is the model id of the binary format.
struct CameraModelInfo {
  const char* name;
  size_t num_params;
};
constexpr CameraModelInfo kCameraModels[] = {{"SIMPLE_PINHOLE", 3},
                                             {"PINHOLE", 4},
                                             {"SIMPLE_RADIAL", 4},
                                             {"RADIAL", 5},
                                             {"OPENCV", 8},
                                             {"OPENCV_FISHEYE", 8},
                                             {"FULL_OPENCV", 12},
                                             {"FOV", 5},
                                             {"SIMPLE_RADIAL_FISHEYE", 4},
                                             {"RADIAL_FISHEYE", 5},
                                             {"THIN_PRISM_FISHEYE", 12}};
constexpr int kNumCameraModels = sizeof(kCameraModels) / sizeof(kCameraModels[0]);

int CameraModelId(const std::string& name) {
  for (int id = 0; id < kNumCameraModels; ++id) {
    if (name == kCameraModels[id].name) return id;
  }
  return -1;
}

std::string KnownModelNames() {
  std::string names;
  for (const auto& model : kCameraModels) {
    names += std::string(names.empty() ? "" : ", ") + model.name;
  }
  return names;
}

// Writers get their models from code, so an inconsistent camera is a programming error.
int CheckedModelId(const ColmapCamera& camera) {
  const int id = CameraModelId(camera.model);
  if (id < 0 || camera.params.size() != kCameraModels[id].num_params) {
    throw InputError("COLMAP camera " + std::to_string(camera.camera_id) + ": model '" +
                     camera.model + "' with " + std::to_string(camera.params.size()) +
                     " parameters is invalid");
  }
  return id;
}

std::string JoinPath(const std::string& dir, const char* file) {
  return (fs::path(dir) / file).string();
}

void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) throw std::runtime_error("cannot write " + path);
}

// ---------------------------------------------------------------------------------------------
// Text format.

class TextLineParser {
 public:
  TextLineParser(const std::string& path, int line_number, std::string_view line,
                 const char* expected)
      : path_(path),
        line_number_(line_number),
        tokens_(text::SplitWhitespace(line)),
        expected_(expected) {}

  size_t size() const { return tokens_.size(); }
  std::string_view token(size_t i) const { return tokens_[i]; }

  [[noreturn]] void Fail(const std::string& message) const {
    ThrowInput(path_, line_number_, message + " (expected " + expected_ + ")");
  }
  double Double(size_t i, const char* field) const {
    double value;
    if (!text::ParseDouble(tokens_[i], &value)) Fail(BadField(i, field, "a finite number"));
    return value;
  }
  template <typename Int>
  Int Integer(size_t i, const char* field) const {
    Int value;
    if (!text::ParseInt(tokens_[i], &value)) Fail(BadField(i, field, "an unsigned integer"));
    return value;
  }

 private:
  std::string BadField(size_t i, const char* field, const char* kind) const {
    return std::string(field) + " '" + std::string(tokens_[i]) + "' is not " + kind;
  }

  const std::string& path_;
  int line_number_;
  std::vector<std::string_view> tokens_;
  const char* expected_;
};

bool IsDataLine(std::string_view line) {
  const std::string_view trimmed = text::Trim(line);
  return !trimmed.empty() && trimmed.front() != '#';
}

void ReadCamerasText(const std::string& path, ColmapModel* model) {
  const std::string contents = ReadTextFile(path);
  const auto lines = text::SplitLines(contents);
  for (size_t k = 0; k < lines.size(); ++k) {
    if (!IsDataLine(lines[k])) continue;
    const int line_number = static_cast<int>(k + 1);
    const TextLineParser p(path, line_number, lines[k], "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    if (p.size() < 4) p.Fail("too few fields");
    ColmapCamera camera;
    camera.camera_id = p.Integer<uint32_t>(0, "CAMERA_ID");
    camera.model = std::string(p.token(1));
    const int model_id = CameraModelId(camera.model);
    if (model_id < 0) {
      p.Fail("unknown camera model '" + camera.model + "', COLMAP 3.8 knows " + KnownModelNames());
    }
    camera.width = p.Integer<uint64_t>(2, "WIDTH");
    camera.height = p.Integer<uint64_t>(3, "HEIGHT");
    const size_t num_params = kCameraModels[model_id].num_params;
    if (p.size() != 4 + num_params) {
      p.Fail(camera.model + " has " + std::to_string(num_params) + " parameters, got " +
             std::to_string(p.size() - 4));
    }
    for (size_t i = 0; i < num_params; ++i) camera.params.push_back(p.Double(4 + i, "parameter"));
    if (!model->cameras.emplace(camera.camera_id, camera).second) {
      p.Fail("camera id " + std::to_string(camera.camera_id) + " appears twice");
    }
  }
}

void ReadImagesText(const std::string& path, ColmapModel* model) {
  const std::string contents = ReadTextFile(path);
  const auto lines = text::SplitLines(contents);
  for (size_t k = 0; k < lines.size(); ++k) {
    if (!IsDataLine(lines[k])) continue;
    const int line_number = static_cast<int>(k + 1);
    const TextLineParser p(path, line_number, lines[k],
                           "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    if (p.size() != 10) p.Fail("got " + std::to_string(p.size()) + " fields");
    ColmapImage image;
    image.image_id = p.Integer<uint32_t>(0, "IMAGE_ID");
    const Eigen::Quaterniond q(p.Double(1, "QW"), p.Double(2, "QX"), p.Double(3, "QY"),
                               p.Double(4, "QZ"));
    if (!(q.norm() > 1e-12)) p.Fail("quaternion has zero norm");
    image.cam_from_world.rotation = q.normalized();
    for (int i = 0; i < 3; ++i) {
      image.cam_from_world.translation[i] = p.Double(5 + i, "translation");
    }
    image.camera_id = p.Integer<uint32_t>(8, "CAMERA_ID");
    image.name = std::string(p.token(9));
    if (!model->cameras.count(image.camera_id)) {
      p.Fail("camera id " + std::to_string(image.camera_id) + " is not in cameras.txt");
    }
    // As in COLMAP, the line right after an image line holds its keypoints, even when empty.
    if (k + 1 < lines.size()) {
      ++k;
      const TextLineParser q(path, line_number + 1, lines[k], "POINTS2D[] as (X, Y, POINT3D_ID)");
      if (q.size() % 3 != 0) q.Fail(std::to_string(q.size()) + " values, not a multiple of 3");
      for (size_t i = 0; i < q.size(); i += 3) {
        image.points2D.emplace_back(q.Double(i, "X"), q.Double(i + 1, "Y"));
        image.point3D_ids.push_back(
            q.token(i + 2) == "-1" ? kInvalidPoint3DId : q.Integer<uint64_t>(i + 2, "POINT3D_ID"));
      }
    }
    if (!model->images.emplace(image.image_id, image).second) {
      p.Fail("image id " + std::to_string(image.image_id) + " appears twice");
    }
  }
}

void ReadPoints3DText(const std::string& path, ColmapModel* model) {
  const std::string contents = ReadTextFile(path);
  const auto lines = text::SplitLines(contents);
  for (size_t k = 0; k < lines.size(); ++k) {
    if (!IsDataLine(lines[k])) continue;
    const TextLineParser p(path, static_cast<int>(k + 1), lines[k],
                           "POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)");
    if (p.size() < 8 || (p.size() - 8) % 2 != 0) {
      p.Fail("got " + std::to_string(p.size()) + " fields");
    }
    ColmapPoint3D point;
    point.point3D_id = p.Integer<uint64_t>(0, "POINT3D_ID");
    for (int i = 0; i < 3; ++i) point.xyz[i] = p.Double(1 + i, "coordinate");
    for (int i = 0; i < 3; ++i) point.rgb[i] = p.Integer<uint8_t>(4 + i, "colour");
    point.error = p.Double(7, "ERROR");
    for (size_t i = 8; i < p.size(); i += 2) {
      point.track.push_back(
          {p.Integer<uint32_t>(i, "IMAGE_ID"), p.Integer<uint32_t>(i + 1, "POINT2D_IDX")});
    }
    if (!model->points3D.emplace(point.point3D_id, point).second) {
      p.Fail("point id " + std::to_string(point.point3D_id) + " appears twice");
    }
  }
}

std::string CamerasText(const ColmapModel& model) {
  std::ostringstream out;
  out << "# Camera list with one line of data per camera:\n"
      << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
      << "# Number of cameras: " << model.cameras.size() << "\n";
  for (const auto& [id, camera] : model.cameras) {
    CheckedModelId(camera);
    out << id << ' ' << camera.model << ' ' << camera.width << ' ' << camera.height;
    for (const double param : camera.params) out << ' ' << text::FormatDouble(param);
    out << '\n';
  }
  return out.str();
}

}  // namespace

bool ColmapTextHoldsName(const std::string& name) {
  return !name.empty() && text::SplitWhitespace(name).size() == 1 && name == text::Trim(name);
}

namespace {

std::string ImagesText(const ColmapModel& model) {
  size_t num_observations = 0;
  for (const auto& [id, image] : model.images) num_observations += image.points2D.size();
  std::ostringstream out;
  out << "# Image list with two lines of data per image:\n"
      << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
      << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
      << "# Number of images: " << model.images.size() << ", mean observations per image: "
      << (model.images.empty() ? 0.0 : double(num_observations) / model.images.size()) << "\n";
  for (const auto& [id, image] : model.images) {
    if (!ColmapTextHoldsName(image.name)) {
      throw InputError("image name '" + image.name +
                       "' is empty or has whitespace; COLMAP text cannot hold it");
    }
    if (image.points2D.size() != image.point3D_ids.size()) {
      throw std::invalid_argument("image " + image.name + ": points2D and point3D_ids differ");
    }
    const Eigen::Quaterniond q = image.cam_from_world.rotation.normalized();
    const Eigen::Vector3d& t = image.cam_from_world.translation;
    out << id;
    for (const double v : {q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()}) {
      out << ' ' << text::FormatDouble(v);
    }
    out << ' ' << image.camera_id << ' ' << image.name << '\n';
    for (size_t i = 0; i < image.points2D.size(); ++i) {
      if (i > 0) out << ' ';
      out << text::FormatDouble(image.points2D[i].x()) << ' '
          << text::FormatDouble(image.points2D[i].y()) << ' ';
      if (image.point3D_ids[i] == kInvalidPoint3DId) {
        out << -1;
      } else {
        out << image.point3D_ids[i];
      }
    }
    out << '\n';
  }
  return out.str();
}

std::string Points3DText(const ColmapModel& model) {
  size_t track_elements = 0;
  for (const auto& [id, point] : model.points3D) track_elements += point.track.size();
  std::ostringstream out;
  out << "# 3D point list with one line of data per point:\n"
      << "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
      << "# Number of points: " << model.points3D.size() << ", mean track length: "
      << (model.points3D.empty() ? 0.0 : double(track_elements) / model.points3D.size()) << "\n";
  for (const auto& [id, point] : model.points3D) {
    out << id;
    for (int i = 0; i < 3; ++i) out << ' ' << text::FormatDouble(point.xyz[i]);
    for (int i = 0; i < 3; ++i) out << ' ' << int(point.rgb[i]);
    out << ' ' << text::FormatDouble(point.error);
    for (const auto& element : point.track) {
      out << ' ' << element.image_id << ' ' << element.point2D_idx;
    }
    out << '\n';
  }
  return out.str();
}

// ---------------------------------------------------------------------------------------------
// Binary format: little-endian, written byte by byte so the layout does not depend on the host.

template <typename T>
using UnsignedOfSize = std::conditional_t<sizeof(T) == 1, uint8_t,
                                          std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>;

class BinaryWriter {
 public:
  template <typename T>
  void Put(T value) {
    static_assert(sizeof(T) == 1 || sizeof(T) == 4 || sizeof(T) == 8);
    UnsignedOfSize<T> bits;
    std::memcpy(&bits, &value, sizeof(T));
    for (size_t i = 0; i < sizeof(T); ++i) bytes_.push_back(char((bits >> (8 * i)) & 0xff));
  }
  void PutString(const std::string& s) { bytes_.append(s.c_str(), s.size() + 1); }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

class BinaryReader {
 public:
  explicit BinaryReader(const std::string& path) : path_(path), bytes_(ReadTextFile(path)) {}

  template <typename T>
  T Get(const std::string& what) {
    static_assert(sizeof(T) == 1 || sizeof(T) == 4 || sizeof(T) == 8);
    Require(sizeof(T), what);
    UnsignedOfSize<T> bits = 0;
    for (size_t i = 0; i < sizeof(T); ++i) {
      bits |= UnsignedOfSize<T>(static_cast<uint8_t>(bytes_[pos_ + i])) << (8 * i);
    }
    pos_ += sizeof(T);
    T value;
    std::memcpy(&value, &bits, sizeof(T));
    return value;
  }
  std::string GetString(const std::string& what) {
    const size_t end = bytes_.find('\0', pos_);
    if (end == std::string::npos) Truncated(what + " (no terminating null byte)");
    std::string s = bytes_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return s;
  }
  // Counts come from the file; checking them against the bytes left keeps a corrupt count from
  // turning into a huge allocation before the truncation is noticed.
  uint64_t GetCount(size_t min_bytes_per_item, const std::string& what) {
    const uint64_t count = Get<uint64_t>(what);
    if (count > (bytes_.size() - pos_) / min_bytes_per_item) {
      Truncated(what + " = " + std::to_string(count) + ", more items than bytes left");
    }
    return count;
  }
  void ExpectEnd() const {
    if (pos_ != bytes_.size()) {
      ThrowInput(path_, 0,
                 std::to_string(bytes_.size() - pos_) +
                     " unexpected bytes after the last record (file size " +
                     std::to_string(bytes_.size()) + ")");
    }
  }
  [[noreturn]] void Fail(const std::string& message) const {
    ThrowInput(path_, 0, message + " (at byte " + std::to_string(pos_) + ")");
  }

 private:
  void Require(size_t n, const std::string& what) const {
    if (bytes_.size() - pos_ < n) Truncated(what);
  }
  [[noreturn]] void Truncated(const std::string& what) const {
    ThrowInput(path_, 0,
               "unexpected end of file at byte " + std::to_string(pos_) + " of " +
                   std::to_string(bytes_.size()) + " while reading " + what);
  }

  std::string path_;
  std::string bytes_;
  size_t pos_ = 0;
};

void ReadCamerasBinary(const std::string& path, ColmapModel* model) {
  BinaryReader in(path);
  const uint64_t count = in.GetCount(24, "number of cameras");
  for (uint64_t k = 0; k < count; ++k) {
    const std::string where = "camera " + std::to_string(k + 1) + " of " + std::to_string(count);
    ColmapCamera camera;
    camera.camera_id = in.Get<uint32_t>(where + ": camera_id");
    const int32_t model_id = in.Get<int32_t>(where + ": model_id");
    if (model_id < 0 || model_id >= kNumCameraModels) {
      in.Fail(where + ": unknown camera model id " + std::to_string(model_id) +
              " (COLMAP 3.8 knows 0-" + std::to_string(kNumCameraModels - 1) + ": " +
              KnownModelNames() + ")");
    }
    camera.model = kCameraModels[model_id].name;
    camera.width = in.Get<uint64_t>(where + ": width");
    camera.height = in.Get<uint64_t>(where + ": height");
    for (size_t i = 0; i < kCameraModels[model_id].num_params; ++i) {
      camera.params.push_back(in.Get<double>(where + ": parameters"));
    }
    if (!model->cameras.emplace(camera.camera_id, camera).second) {
      in.Fail(where + ": camera id " + std::to_string(camera.camera_id) + " appears twice");
    }
  }
  in.ExpectEnd();
}

void ReadImagesBinary(const std::string& path, ColmapModel* model) {
  BinaryReader in(path);
  const uint64_t count = in.GetCount(73, "number of images");
  for (uint64_t k = 0; k < count; ++k) {
    const std::string where = "image " + std::to_string(k + 1) + " of " + std::to_string(count);
    ColmapImage image;
    image.image_id = in.Get<uint32_t>(where + ": image_id");
    double wxyz[4];
    for (double& v : wxyz) v = in.Get<double>(where + ": qvec");
    const Eigen::Quaterniond q(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    if (!(q.norm() > 1e-12)) in.Fail(where + ": quaternion has zero norm");
    image.cam_from_world.rotation = q.normalized();
    for (int i = 0; i < 3; ++i) {
      image.cam_from_world.translation[i] = in.Get<double>(where + ": tvec");
    }
    image.camera_id = in.Get<uint32_t>(where + ": camera_id");
    image.name = in.GetString(where + ": name");
    if (!model->cameras.count(image.camera_id)) {
      in.Fail(where + " (" + image.name + "): camera id " + std::to_string(image.camera_id) +
              " is not in cameras.bin");
    }
    const uint64_t num_points = in.GetCount(24, where + ": num_points2D");
    image.points2D.reserve(num_points);
    image.point3D_ids.reserve(num_points);
    for (uint64_t i = 0; i < num_points; ++i) {
      const double x = in.Get<double>(where + ": points2D");
      const double y = in.Get<double>(where + ": points2D");
      image.points2D.emplace_back(x, y);
      image.point3D_ids.push_back(in.Get<uint64_t>(where + ": points2D"));
    }
    if (!model->images.emplace(image.image_id, image).second) {
      in.Fail(where + ": image id " + std::to_string(image.image_id) + " appears twice");
    }
  }
  in.ExpectEnd();
}

void ReadPoints3DBinary(const std::string& path, ColmapModel* model) {
  BinaryReader in(path);
  const uint64_t count = in.GetCount(51, "number of points");
  for (uint64_t k = 0; k < count; ++k) {
    const std::string where = "point " + std::to_string(k + 1) + " of " + std::to_string(count);
    ColmapPoint3D point;
    point.point3D_id = in.Get<uint64_t>(where + ": point3D_id");
    for (int i = 0; i < 3; ++i) point.xyz[i] = in.Get<double>(where + ": xyz");
    for (int i = 0; i < 3; ++i) point.rgb[i] = in.Get<uint8_t>(where + ": rgb");
    point.error = in.Get<double>(where + ": error");
    const uint64_t track_length = in.GetCount(8, where + ": track_length");
    point.track.resize(track_length);
    for (auto& element : point.track) {
      element.image_id = in.Get<uint32_t>(where + ": track");
      element.point2D_idx = in.Get<uint32_t>(where + ": track");
    }
    if (!model->points3D.emplace(point.point3D_id, std::move(point)).second) {
      in.Fail(where + ": point id appears twice");
    }
  }
  in.ExpectEnd();
}

std::string CamerasBinary(const ColmapModel& model) {
  BinaryWriter out;
  out.Put<uint64_t>(model.cameras.size());
  for (const auto& [id, camera] : model.cameras) {
    out.Put<uint32_t>(id);
    out.Put<int32_t>(CheckedModelId(camera));
    out.Put<uint64_t>(camera.width);
    out.Put<uint64_t>(camera.height);
    for (const double param : camera.params) out.Put<double>(param);
  }
  return out.bytes();
}

std::string ImagesBinary(const ColmapModel& model) {
  BinaryWriter out;
  out.Put<uint64_t>(model.images.size());
  for (const auto& [id, image] : model.images) {
    if (image.name.empty() || image.name.find('\0') != std::string::npos) {
      throw InputError("image " + std::to_string(id) + " has an empty or invalid name");
    }
    if (image.points2D.size() != image.point3D_ids.size()) {
      throw std::invalid_argument("image " + image.name + ": points2D and point3D_ids differ");
    }
    const Eigen::Quaterniond q = image.cam_from_world.rotation.normalized();
    out.Put<uint32_t>(id);
    for (const double v : {q.w(), q.x(), q.y(), q.z()}) out.Put<double>(v);
    for (int i = 0; i < 3; ++i) out.Put<double>(image.cam_from_world.translation[i]);
    out.Put<uint32_t>(image.camera_id);
    out.PutString(image.name);
    out.Put<uint64_t>(image.points2D.size());
    for (size_t i = 0; i < image.points2D.size(); ++i) {
      out.Put<double>(image.points2D[i].x());
      out.Put<double>(image.points2D[i].y());
      out.Put<uint64_t>(image.point3D_ids[i]);
    }
  }
  return out.bytes();
}

std::string Points3DBinary(const ColmapModel& model) {
  BinaryWriter out;
  out.Put<uint64_t>(model.points3D.size());
  for (const auto& [id, point] : model.points3D) {
    out.Put<uint64_t>(id);
    for (int i = 0; i < 3; ++i) out.Put<double>(point.xyz[i]);
    for (int i = 0; i < 3; ++i) out.Put<uint8_t>(point.rgb[i]);
    out.Put<double>(point.error);
    out.Put<uint64_t>(point.track.size());
    for (const auto& element : point.track) {
      out.Put<uint32_t>(element.image_id);
      out.Put<uint32_t>(element.point2D_idx);
    }
  }
  return out.bytes();
}

}  // namespace

ColmapModel ReadColmapModel(const std::string& dir) {
  if (fs::exists(JoinPath(dir, "cameras.bin"))) return ReadColmapModelBinary(dir);
  if (fs::exists(JoinPath(dir, "cameras.txt"))) return ReadColmapModelText(dir);
  ThrowInput(dir, 0, "not a COLMAP model: neither cameras.bin nor cameras.txt found");
}

ColmapModel ReadColmapModelText(const std::string& dir) {
  ColmapModel model;
  ReadCamerasText(JoinPath(dir, "cameras.txt"), &model);
  ReadImagesText(JoinPath(dir, "images.txt"), &model);
  ReadPoints3DText(JoinPath(dir, "points3D.txt"), &model);
  return model;
}

ColmapModel ReadColmapModelBinary(const std::string& dir) {
  ColmapModel model;
  ReadCamerasBinary(JoinPath(dir, "cameras.bin"), &model);
  ReadImagesBinary(JoinPath(dir, "images.bin"), &model);
  ReadPoints3DBinary(JoinPath(dir, "points3D.bin"), &model);
  return model;
}

void WriteColmapModelText(const ColmapModel& model, const std::string& dir) {
  // Serialize first so an invalid model throws before the folder is touched.
  const std::string cameras = CamerasText(model), images = ImagesText(model),
                    points = Points3DText(model);
  WriteDirectoryAtomically(dir, [&](const std::string& tmp) {
    WriteBytes(JoinPath(tmp, "cameras.txt"), cameras);
    WriteBytes(JoinPath(tmp, "images.txt"), images);
    WriteBytes(JoinPath(tmp, "points3D.txt"), points);
  });
}

void WriteColmapModelBinary(const ColmapModel& model, const std::string& dir) {
  const std::string cameras = CamerasBinary(model), images = ImagesBinary(model),
                    points = Points3DBinary(model);
  WriteDirectoryAtomically(dir, [&](const std::string& tmp) {
    WriteBytes(JoinPath(tmp, "cameras.bin"), cameras);
    WriteBytes(JoinPath(tmp, "images.bin"), images);
    WriteBytes(JoinPath(tmp, "points3D.bin"), points);
  });
}

CameraIntrinsics IntrinsicsFromColmap(const ColmapCamera& camera) {
  const std::string where =
      "COLMAP camera " + std::to_string(camera.camera_id) + " (" + camera.model + ")";
  const int model_id = CameraModelId(camera.model);
  if (model_id < 0 || camera.params.size() != kCameraModels[model_id].num_params) {
    throw InputError(where + ": unknown model or wrong number of parameters (" +
                     std::to_string(camera.params.size()) + ")");
  }
  const std::vector<double>& p = camera.params;
  // (fx, fy, cx, cy, k1, k2, p1, p2) in COLMAP's pixel convention.
  std::array<double, kNumIntrinsics> q{0, 0, 0, 0, 0, 0, 0, 0};
  if (camera.model == "SIMPLE_PINHOLE" || camera.model == "SIMPLE_RADIAL" ||
      camera.model == "RADIAL") {
    q = {p[0], p[0], p[1], p[2], 0, 0, 0, 0};
    if (p.size() >= 4) q[kK1] = p[3];
    if (p.size() >= 5) q[kK2] = p[4];
  } else if (camera.model == "PINHOLE" || camera.model == "OPENCV") {
    for (size_t i = 0; i < p.size(); ++i) q[i] = p[i];
  } else {
    throw InputError(where +
                     ": model not supported; raytime reads SIMPLE_PINHOLE, PINHOLE, "
                     "SIMPLE_RADIAL, RADIAL and OPENCV");
  }
  if (camera.width > uint64_t(std::numeric_limits<int>::max()) ||
      camera.height > uint64_t(std::numeric_limits<int>::max())) {
    throw InputError(where + ": image size out of range");
  }
  CameraIntrinsics intrinsics;
  intrinsics.width = static_cast<int>(camera.width);
  intrinsics.height = static_cast<int>(camera.height);
  intrinsics.params = q;
  intrinsics.params[kCx] -= 0.5;
  intrinsics.params[kCy] -= 0.5;
  return intrinsics;
}

ColmapCamera ColmapFromIntrinsics(const CameraIntrinsics& intrinsics, uint32_t camera_id) {
  ColmapCamera camera;
  camera.camera_id = camera_id;
  camera.width = static_cast<uint64_t>(intrinsics.width);
  camera.height = static_cast<uint64_t>(intrinsics.height);
  camera.model = intrinsics.HasDistortion() ? "OPENCV" : "PINHOLE";
  const size_t num_params = intrinsics.HasDistortion() ? 8 : 4;
  camera.params.assign(intrinsics.params.begin(), intrinsics.params.begin() + num_params);
  camera.params[kCx] += 0.5;
  camera.params[kCy] += 0.5;
  return camera;
}

void FromColmapModel(const ColmapModel& model, ImageSet* images, PoseSet* poses) {
  ImageSet image_set;
  PoseSet pose_set;
  // Only cameras some image uses: an unused camera of an unsupported model is no reason to fail.
  std::map<uint32_t, int> camera_index;
  for (const auto& [id, image] : model.images) {
    if (!model.cameras.count(image.camera_id)) {
      throw InputError("COLMAP image " + image.name + " refers to missing camera " +
                       std::to_string(image.camera_id));
    }
    camera_index[image.camera_id] = 0;
  }
  for (auto& [id, index] : camera_index) {
    index = static_cast<int>(image_set.cameras.size());
    image_set.cameras.push_back(IntrinsicsFromColmap(model.cameras.at(id)));
  }
  for (const auto& [id, image] : model.images) {
    const int index = camera_index.at(image.camera_id);
    const CameraIntrinsics& intrinsics = image_set.cameras[index];
    image_set.images.push_back({image.name, intrinsics.width, intrinsics.height, index});
    if (!pose_set.world_from_cam.emplace(image.name, image.cam_from_world.Inverse()).second) {
      throw InputError("COLMAP model has two images named " + image.name);
    }
  }
  std::sort(image_set.images.begin(), image_set.images.end(),
            [](const ImageInfo& a, const ImageInfo& b) { return a.name < b.name; });
  if (images) *images = std::move(image_set);
  if (poses) *poses = std::move(pose_set);
}

ColmapModel ToColmapModel(const ImageSet& images, const PoseSet& poses) {
  const NameJoin join = JoinNames(Names(images), Names(poses));
  if (!join.only_right.empty()) {
    throw InputError("poses without an image: " + join.Describe("images", "poses"));
  }
  ColmapModel model;
  for (size_t c = 0; c < images.cameras.size(); ++c) {
    const auto camera_id = static_cast<uint32_t>(c + 1);
    model.cameras[camera_id] = ColmapFromIntrinsics(images.cameras[c], camera_id);
  }
  for (size_t i = 0; i < images.images.size(); ++i) {
    const ImageInfo& info = images.images[i];
    const auto pose = poses.world_from_cam.find(info.name);
    if (pose == poses.world_from_cam.end()) continue;
    if (info.camera_index < 0 || size_t(info.camera_index) >= images.cameras.size()) {
      throw std::invalid_argument("image " + info.name + " has camera index " +
                                  std::to_string(info.camera_index) + " out of range");
    }
    ColmapImage image;
    image.image_id = static_cast<uint32_t>(i + 1);
    image.name = info.name;
    image.camera_id = static_cast<uint32_t>(info.camera_index + 1);
    image.cam_from_world = pose->second.Inverse();
    model.images[image.image_id] = image;
  }
  return model;
}

}  // namespace raytime

#include "splat/splat_render.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>

#include "core/atomic_file.h"
#include "core/error.h"

namespace raytime {
namespace {

// The 3DGS code's real spherical-harmonics constants (utils/sh_utils.py, the CUDA rasterizer).
constexpr float kSh0 = 0.28209479177387814f;
constexpr float kSh1 = 0.4886025119029199f;
constexpr float kSh2[] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f,
                          -1.0925484305920792f, 0.5462742152960396f};
constexpr float kSh3[] = {-0.5900435899266435f, 2.890611442640554f,   -0.4570457994644658f,
                          0.3731763325901154f,  -0.4570457994644658f, 1.445305721320277f,
                          -0.5900435899266435f};

constexpr int kTile = 16;
constexpr float kLowPassPx2 = 0.3f;      // added to the 2D covariance's diagonal
constexpr float kMinAlpha = 1.0f / 255;  // contributions below one grey level are skipped
constexpr float kMinTransmittance = 1e-4f;

// A PLY property: its name, its byte size in a binary body, and how to read it as a double.
struct PlyProperty {
  std::string name;
  std::string type;
  int size = 0;
};

int PlyTypeSize(const std::string& type) {
  static const std::map<std::string, int> kSizes = {
      {"char", 1},   {"int8", 1},    {"uchar", 1},  {"uint8", 1},  {"short", 2}, {"int16", 2},
      {"ushort", 2}, {"uint16", 2},  {"int", 4},    {"int32", 4},  {"uint", 4},  {"uint32", 4},
      {"float", 4},  {"float32", 4}, {"double", 8}, {"float64", 8}};
  const auto it = kSizes.find(type);
  return it == kSizes.end() ? 0 : it->second;
}

double ReadBinaryValue(const char* data, const std::string& type) {
  const auto read = [&](auto value) {
    std::memcpy(&value, data, sizeof(value));
    return static_cast<double>(value);
  };
  if (type == "float" || type == "float32") return read(float());
  if (type == "double" || type == "float64") return read(double());
  if (type == "uchar" || type == "uint8") return read(uint8_t());
  if (type == "char" || type == "int8") return read(int8_t());
  if (type == "short" || type == "int16") return read(int16_t());
  if (type == "ushort" || type == "uint16") return read(uint16_t());
  if (type == "int" || type == "int32") return read(int32_t());
  return read(uint32_t());
}

struct PlyHeader {
  bool binary = true;
  size_t num_vertices = 0;
  std::vector<PlyProperty> properties;  // of the vertex element
};

PlyHeader ReadPlyHeader(const std::string& path, std::istream& in) {
  PlyHeader header;
  std::string line;
  int line_number = 0;
  bool in_vertex = false, seen_vertex = false;
  const auto fail = [&](const std::string& what) { ThrowInput(path, line_number, what); };
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line_number == 1) {
      if (line != "ply") fail("not a PLY file (its first line is not 'ply')");
      continue;
    }
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "format") {
      std::string format;
      words >> format;
      if (format == "ascii") {
        header.binary = false;
      } else if (format != "binary_little_endian") {
        fail("PLY format '" + format + "' is not read (binary_little_endian or ascii)");
      }
    } else if (keyword == "element") {
      std::string name;
      size_t count = 0;
      words >> name >> count;
      in_vertex = name == "vertex";
      if (in_vertex) {
        header.num_vertices = count;
        seen_vertex = true;
      } else if (!seen_vertex) {
        fail("element '" + name + "' before the vertex element is not read");
      }
    } else if (keyword == "property" && in_vertex) {
      PlyProperty property;
      words >> property.type >> property.name;
      if (property.type == "list") fail("a list property in the vertex element is not read");
      property.size = PlyTypeSize(property.type);
      if (property.size == 0) fail("unknown PLY property type '" + property.type + "'");
      header.properties.push_back(property);
    } else if (keyword == "end_header") {
      if (!seen_vertex) fail("no vertex element: not a 3DGS point cloud");
      return header;  // `in` is at the body
    }
  }
  ThrowInput(path, line_number, "the PLY header has no end_header line");
}

}  // namespace

GaussianSplats ReadGaussianSplatPly(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInput(path, 0, "cannot open the 3DGS .ply");
  const PlyHeader header = ReadPlyHeader(path, in);
  std::map<std::string, int> column;
  for (size_t p = 0; p < header.properties.size(); ++p) {
    column[header.properties[p].name] = static_cast<int>(p);
  }
  const auto need = [&](const std::string& name) {
    const auto it = column.find(name);
    if (it == column.end()) {
      ThrowInput(path, 0, "the vertex element has no '" + name + "' property: not a 3DGS .ply");
    }
    return it->second;
  };
  const int x = need("x"), y = need("y"), z = need("z"), opacity = need("opacity");
  int scale[3], rot[4], dc[3];
  for (int k = 0; k < 3; ++k) scale[k] = need("scale_" + std::to_string(k));
  for (int k = 0; k < 4; ++k) rot[k] = need("rot_" + std::to_string(k));
  for (int k = 0; k < 3; ++k) dc[k] = need("f_dc_" + std::to_string(k));
  std::vector<int> rest;
  while (column.count("f_rest_" + std::to_string(rest.size()))) {
    rest.push_back(column.at("f_rest_" + std::to_string(rest.size())));
  }
  GaussianSplats splats;
  const int per_channel = static_cast<int>(rest.size()) / 3;  // (d + 1)² − 1
  for (int degree = 0; degree <= 3; ++degree) {
    if ((degree + 1) * (degree + 1) - 1 == per_channel && rest.size() % 3 == 0) {
      splats.sh_degree = degree;
      break;
    }
    if (degree == 3) {
      ThrowInput(path, 0,
                 std::to_string(rest.size()) +
                     " f_rest properties: not 3 × ((d + 1)² − 1) for a degree d ≤ 3");
    }
  }
  const int num_coefficients = per_channel + 1;

  const size_t n = header.num_vertices;
  std::vector<double> row(header.properties.size());
  size_t stride = 0;
  for (const PlyProperty& p : header.properties) stride += p.size;
  std::vector<char> body;
  if (header.binary) {
    body.resize(stride * n);
    in.read(body.data(), static_cast<std::streamsize>(body.size()));
    if (static_cast<size_t>(in.gcount()) != body.size()) {
      ThrowInput(path, 0,
                 "the body is truncated: " + std::to_string(in.gcount()) + " of " +
                     std::to_string(body.size()) + " bytes for " + std::to_string(n) +
                     " Gaussians");
    }
  }
  splats.means.reserve(n);
  for (size_t v = 0; v < n; ++v) {
    if (header.binary) {
      const char* record = body.data() + v * stride;
      size_t offset = 0;
      for (size_t p = 0; p < header.properties.size(); ++p) {
        row[p] = ReadBinaryValue(record + offset, header.properties[p].type);
        offset += header.properties[p].size;
      }
    } else {
      for (double& value : row) {
        if (!(in >> value)) {
          ThrowInput(
              path, 0,
              "the ASCII body ends at Gaussian " + std::to_string(v) + " of " + std::to_string(n));
        }
      }
    }
    splats.means.emplace_back(row[x], row[y], row[z]);
    splats.log_scales.emplace_back(row[scale[0]], row[scale[1]], row[scale[2]]);
    splats.rotations.emplace_back(row[rot[0]], row[rot[1]], row[rot[2]], row[rot[3]]);
    splats.opacity_logits.push_back(static_cast<float>(row[opacity]));
    Eigen::VectorXf sh(3 * num_coefficients);
    for (int c = 0; c < 3; ++c) {
      sh(c) = static_cast<float>(row[dc[c]]);
      for (int k = 1; k < num_coefficients; ++k) {
        sh(3 * k + c) = static_cast<float>(row[rest[c * per_channel + (k - 1)]]);
      }
    }
    splats.sh.push_back(std::move(sh));
  }
  return splats;
}

void WriteGaussianSplatPly(const GaussianSplats& splats, const std::string& path) {
  const int num_coefficients = (splats.sh_degree + 1) * (splats.sh_degree + 1);
  const int per_channel = num_coefficients - 1;
  std::ostringstream out;
  out << "ply\nformat binary_little_endian 1.0\nelement vertex " << splats.size() << "\n";
  for (const char* name : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"}) {
    out << "property float " << name << "\n";
  }
  for (int k = 0; k < 3 * per_channel; ++k) out << "property float f_rest_" << k << "\n";
  out << "property float opacity\n";
  for (int k = 0; k < 3; ++k) out << "property float scale_" << k << "\n";
  for (int k = 0; k < 4; ++k) out << "property float rot_" << k << "\n";
  out << "end_header\n";
  std::vector<float> record;
  for (size_t g = 0; g < splats.size(); ++g) {
    record.assign({splats.means[g].x(), splats.means[g].y(), splats.means[g].z(), 0, 0, 0});
    for (int c = 0; c < 3; ++c) record.push_back(splats.sh[g](c));
    for (int c = 0; c < 3; ++c) {
      for (int k = 1; k < num_coefficients; ++k) record.push_back(splats.sh[g](3 * k + c));
    }
    record.push_back(splats.opacity_logits[g]);
    for (int k = 0; k < 3; ++k) record.push_back(splats.log_scales[g](k));
    for (int k = 0; k < 4; ++k) record.push_back(splats.rotations[g](k));
    out.write(reinterpret_cast<const char*>(record.data()),
              static_cast<std::streamsize>(record.size() * sizeof(float)));
  }
  WriteTextFileAtomically(path, out.str());
}

size_t CountNonFiniteGaussians(const GaussianSplats& splats) {
  size_t count = 0;
  for (size_t g = 0; g < splats.size(); ++g) {
    const bool size_zero_or_finite =
        (splats.log_scales[g].array().isFinite() ||
         splats.log_scales[g].array() == -std::numeric_limits<float>::infinity())
            .all();
    const bool finite = splats.means[g].allFinite() && size_zero_or_finite &&
                        splats.rotations[g].allFinite() &&
                        std::isfinite(splats.opacity_logits[g]) && splats.sh[g].allFinite();
    count += finite ? 0 : 1;
  }
  return count;
}

Eigen::Vector3f EvaluateSphericalHarmonics(const Eigen::VectorXf& sh, int degree,
                                           const Eigen::Vector3f& direction) {
  const auto coefficient = [&](int k) { return Eigen::Vector3f(sh.segment<3>(3 * k)); };
  Eigen::Vector3f colour = kSh0 * coefficient(0);
  if (degree < 1) return colour;
  const float x = direction.x(), y = direction.y(), z = direction.z();
  colour += -kSh1 * y * coefficient(1) + kSh1 * z * coefficient(2) - kSh1 * x * coefficient(3);
  if (degree < 2) return colour;
  const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  colour += kSh2[0] * xy * coefficient(4) + kSh2[1] * yz * coefficient(5) +
            kSh2[2] * (2 * zz - xx - yy) * coefficient(6) + kSh2[3] * xz * coefficient(7) +
            kSh2[4] * (xx - yy) * coefficient(8);
  if (degree < 3) return colour;
  colour += kSh3[0] * y * (3 * xx - yy) * coefficient(9) + kSh3[1] * xy * z * coefficient(10) +
            kSh3[2] * y * (4 * zz - xx - yy) * coefficient(11) +
            kSh3[3] * z * (2 * zz - 3 * xx - 3 * yy) * coefficient(12) +
            kSh3[4] * x * (4 * zz - xx - yy) * coefficient(13) +
            kSh3[5] * z * (xx - yy) * coefficient(14) +
            kSh3[6] * x * (xx - 3 * yy) * coefficient(15);
  return colour;
}

namespace {

// A Gaussian as the rasterizer sees it in one view.
struct ProjectedSplat {
  Eigen::Vector2f centre;  // pixels
  Eigen::Vector3f conic;   // the 2D covariance's inverse: a, b, c of [[a b] [b c]]
  Eigen::Vector3f colour;  // RGB, ≥ 0
  float opacity = 0.0f;
  float depth = 0.0f;
  int radius = 0;  // pixels, 3σ of the major axis
  // clip_to_box: the pixels it may reach, [x0, x1) × [y0, y1).
  int x0 = 0, x1 = 0, y0 = 0, y1 = 0;
};

// EWA projection of Gaussian g (3DGS's preprocess): false when it is culled (behind the near
// plane, degenerate, or reaching no pixel).
bool ProjectSplat(const GaussianSplats& splats, size_t g, const Eigen::Matrix3f& cam_from_world,
                  const Eigen::Vector3f& centre, const CameraIntrinsics& camera, float near,
                  bool centred_principal_point, ProjectedSplat* out) {
  const Eigen::Vector3f t = cam_from_world * (splats.means[g] - centre);
  if (t.z() <= near) return false;
  const float fx = static_cast<float>(camera.fx()), fy = static_cast<float>(camera.fy());
  // The Jacobian at a point clamped to 1.3× the field of view, as 3DGS does, so Gaussians far
  // outside the view do not blow up.
  const float limit_x = 1.3f * 0.5f * camera.width / fx, limit_y = 1.3f * 0.5f * camera.height / fy;
  const float tx = std::clamp(t.x() / t.z(), -limit_x, limit_x) * t.z();
  const float ty = std::clamp(t.y() / t.z(), -limit_y, limit_y) * t.z();
  Eigen::Matrix<float, 2, 3> jacobian;
  jacobian << fx / t.z(), 0, -fx * tx / (t.z() * t.z()), 0, fy / t.z(), -fy * ty / (t.z() * t.z());
  const Eigen::Vector4f q = splats.rotations[g];
  const Eigen::Matrix3f rotation =
      Eigen::Quaternionf(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
  const Eigen::Vector3f scale = splats.log_scales[g].array().exp();
  const Eigen::Matrix3f m = rotation * scale.asDiagonal();
  const Eigen::Matrix<float, 2, 3> projection = jacobian * cam_from_world;
  Eigen::Matrix2f covariance = projection * (m * m.transpose()) * projection.transpose();
  covariance(0, 0) += kLowPassPx2;
  covariance(1, 1) += kLowPassPx2;
  const float det = covariance.determinant();
  if (!(det > 0.0f)) return false;
  out->conic =
      Eigen::Vector3f(covariance(1, 1) / det, -covariance(0, 1) / det, covariance(0, 0) / det);
  const float mid = 0.5f * (covariance(0, 0) + covariance(1, 1));
  const float largest = mid + std::sqrt(std::max(0.1f, mid * mid - det));
  out->radius = static_cast<int>(std::ceil(3.0f * std::sqrt(largest)));
  const float cx =
      centred_principal_point ? 0.5f * (camera.width - 1) : static_cast<float>(camera.cx());
  const float cy =
      centred_principal_point ? 0.5f * (camera.height - 1) : static_cast<float>(camera.cy());
  out->centre = Eigen::Vector2f(fx * t.x() / t.z() + cx, fy * t.y() / t.z() + cy);
  if (out->centre.x() + out->radius < 0 || out->centre.y() + out->radius < 0 ||
      out->centre.x() - out->radius > camera.width - 1 ||
      out->centre.y() - out->radius > camera.height - 1) {
    return false;
  }
  const Eigen::Vector3f direction = (splats.means[g] - centre).normalized();
  out->colour =
      (EvaluateSphericalHarmonics(splats.sh[g], splats.sh_degree, direction).array() + 0.5f)
          .max(0.0f);
  out->opacity = 1.0f / (1.0f + std::exp(-splats.opacity_logits[g]));
  out->depth = t.z();
  const float box_x = 3.0f * std::sqrt(covariance(0, 0)),
              box_y = 3.0f * std::sqrt(covariance(1, 1));
  out->x0 = static_cast<int>(std::floor(out->centre.x() - box_x)) - 2;
  out->x1 = static_cast<int>(std::ceil(out->centre.x() + box_x)) + 2;
  out->y0 = static_cast<int>(std::floor(out->centre.y() - box_y)) - 2;
  out->y1 = static_cast<int>(std::ceil(out->centre.y() + box_y)) + 2;
  return true;
}

}  // namespace

SplatRenderOptions SplatRenderOptionsOf(const std::string& trainer) {
  SplatRenderOptions options;
  if (trainer == "inria") {
    options.max_alpha = 0.99f;
    options.centred_principal_point = true;
  } else if (trainer == "opensplat") {
    options.background = Eigen::Vector3f(0.6130f, 0.0101f, 0.3984f);
    options.centred_principal_point = true;
    options.clip_to_box = true;
  }
  return options;
}

cv::Mat RenderGaussianSplats(const GaussianSplats& splats, const CameraIntrinsics& camera,
                             const Rigid3& world_from_cam, const SplatRenderOptions& options) {
  if (camera.width <= 0 || camera.height <= 0 || !(camera.fx() > 0) || !(camera.fy() > 0)) {
    throw std::invalid_argument("RenderGaussianSplats: a camera without size or focal length");
  }
  const Eigen::Matrix3f cam_from_world =
      world_from_cam.rotation.normalized().toRotationMatrix().transpose().cast<float>();
  const Eigen::Vector3f centre = world_from_cam.translation.cast<float>();
  std::vector<ProjectedSplat> projected;
  projected.reserve(splats.size());
  for (size_t g = 0; g < splats.size(); ++g) {
    ProjectedSplat p;
    if (ProjectSplat(splats, g, cam_from_world, centre, camera, static_cast<float>(options.near),
                     options.centred_principal_point, &p)) {
      projected.push_back(p);
    }
  }
  // Front to back: depth, then input order for equal depths (the same image every time).
  std::vector<int> order(projected.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return projected[a].depth < projected[b].depth; });
  const int tiles_x = (camera.width + kTile - 1) / kTile;
  const int tiles_y = (camera.height + kTile - 1) / kTile;
  std::vector<std::vector<int>> tile_lists(static_cast<size_t>(tiles_x) * tiles_y);
  for (const int k : order) {
    const ProjectedSplat& p = projected[k];
    const int x0 = std::max(0, static_cast<int>(std::floor((p.centre.x() - p.radius) / kTile)));
    const int x1 =
        std::min(tiles_x - 1, static_cast<int>(std::floor((p.centre.x() + p.radius) / kTile)));
    const int y0 = std::max(0, static_cast<int>(std::floor((p.centre.y() - p.radius) / kTile)));
    const int y1 =
        std::min(tiles_y - 1, static_cast<int>(std::floor((p.centre.y() + p.radius) / kTile)));
    for (int ty = y0; ty <= y1; ++ty) {
      for (int tx = x0; tx <= x1; ++tx)
        tile_lists[static_cast<size_t>(ty) * tiles_x + tx].push_back(k);
    }
  }

  cv::Mat image(camera.height, camera.width, CV_32FC3);
  const auto render_tile = [&](int tile) {
    const int tx = tile % tiles_x, ty = tile / tiles_x;
    for (int v = ty * kTile; v < std::min(camera.height, (ty + 1) * kTile); ++v) {
      for (int u = tx * kTile; u < std::min(camera.width, (tx + 1) * kTile); ++u) {
        Eigen::Vector3f colour = Eigen::Vector3f::Zero();
        float transmittance = 1.0f;
        for (const int k : tile_lists[tile]) {
          const ProjectedSplat& p = projected[k];
          if (options.clip_to_box && (u < p.x0 || u >= p.x1 || v < p.y0 || v >= p.y1)) continue;
          const float dx = p.centre.x() - u, dy = p.centre.y() - v;
          const float power =
              -0.5f * (p.conic.x() * dx * dx + p.conic.z() * dy * dy) - p.conic.y() * dx * dy;
          if (power > 0.0f) continue;
          const float alpha = std::min(options.max_alpha, p.opacity * std::exp(power));
          if (alpha < kMinAlpha) continue;
          const float next = transmittance * (1.0f - alpha);
          if (next < kMinTransmittance) break;
          colour += p.colour * (alpha * transmittance);
          transmittance = next;
        }
        colour += transmittance * options.background;
        // BGR, as cv::imread orders a photo's channels.
        image.at<cv::Vec3f>(v, u) =
            cv::Vec3f(std::clamp(colour.z(), 0.0f, 1.0f), std::clamp(colour.y(), 0.0f, 1.0f),
                      std::clamp(colour.x(), 0.0f, 1.0f));
      }
    }
  };
  std::unique_ptr<tbb::global_control> threads;
  if (options.num_threads > 0) {
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    options.num_threads);
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, tiles_x * tiles_y),
                    [&](const tbb::blocked_range<int>& range) {
                      for (int tile = range.begin(); tile != range.end(); ++tile) render_tile(tile);
                    });
  return image;
}

}  // namespace raytime

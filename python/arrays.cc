#include "python/arrays.h"

#include <cmath>

#include "core/error.h"
#include "core/geometry.h"
#include "formats/colmap_model.h"

namespace py = pybind11;

namespace raytime::python {

PixelConvention PixelConventionFromName(const std::string& name) {
  PixelConvention convention = PixelConvention::kOpenCv;
  if (EnumFromName(name, &convention)) return convention;
  throw InputError("pixel_convention '" + name + "': expected 'opencv' or 'colmap'");
}

CameraIntrinsics CameraFromDict(const py::dict& camera, PixelConvention convention,
                                const std::string& where) {
  for (const char* key : {"model", "width", "height", "params"}) {
    if (!camera.contains(key)) {
      throw InputError(where + ": no '" + key +
                       "' (a camera is {model, width, height, params}, params in COLMAP's order)");
    }
  }
  ColmapCamera colmap;
  colmap.model = py::str(camera["model"]).cast<std::string>();
  colmap.width = camera["width"].cast<uint64_t>();
  colmap.height = camera["height"].cast<uint64_t>();
  colmap.params = camera["params"].cast<std::vector<double>>();
  CameraIntrinsics intrinsics;
  try {
    intrinsics = IntrinsicsFromColmap(colmap);
  } catch (const InputError& e) {
    throw InputError(where + ": " + e.what());
  }
  // IntrinsicsFromColmap took the principal point as COLMAP's: back to the caller's when OpenCV's.
  if (convention == PixelConvention::kOpenCv) {
    intrinsics.params[kCx] += 0.5;
    intrinsics.params[kCy] += 0.5;
  }
  return intrinsics;
}

py::dict CameraToDict(const CameraIntrinsics& camera, PixelConvention convention) {
  const ColmapCamera colmap = ColmapFromIntrinsics(camera, 1);
  std::vector<double> params = colmap.params;
  // ColmapFromIntrinsics wrote COLMAP's principal point (params 2 and 3 of PINHOLE and OPENCV).
  if (convention == PixelConvention::kOpenCv) {
    params[2] -= 0.5;
    params[3] -= 0.5;
  }
  py::dict out;
  out["model"] = colmap.model;
  out["width"] = colmap.width;
  out["height"] = colmap.height;
  out["params"] = params;
  return out;
}

std::vector<Rigid3> PosesFromArray(const PoseArray& poses, const std::string& what) {
  if (poses.ndim() != 3 || poses.shape(1) != 4 || poses.shape(2) != 4) {
    throw InputError(what + ": expected an (N, 4, 4) array of camera-to-world matrices");
  }
  const auto p = poses.unchecked<3>();
  std::vector<Rigid3> out;
  for (py::ssize_t n = 0; n < poses.shape(0); ++n) {
    Eigen::Matrix3d rotation;
    Eigen::Vector3d centre;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) rotation(r, c) = p(n, r, c);
      centre(r) = p(n, r, 3);
    }
    const std::string problem = RotationMatrixProblem(rotation);
    if (!problem.empty() || !centre.allFinite()) {
      throw InputError(what + "[" + std::to_string(n) + "]: " +
                       (problem.empty() ? std::string("the centre is not finite") : problem));
    }
    if (p(n, 3, 0) != 0 || p(n, 3, 1) != 0 || p(n, 3, 2) != 0 || p(n, 3, 3) != 1) {
      throw InputError(what + "[" + std::to_string(n) + "]: the last row is not 0 0 0 1");
    }
    out.emplace_back(Eigen::Quaterniond(Orthonormalize(rotation)), centre);
  }
  return out;
}

PoseArray PosesToArray(const std::vector<Rigid3>& poses) {
  PoseArray out({static_cast<py::ssize_t>(poses.size()), py::ssize_t{4}, py::ssize_t{4}});
  auto p = out.mutable_unchecked<3>();
  for (size_t n = 0; n < poses.size(); ++n) {
    const Eigen::Matrix3d rotation = poses[n].RotationMatrix();
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        p(n, r, c) =
            r == 3 ? (c == 3 ? 1.0 : 0.0) : (c == 3 ? poses[n].translation(r) : rotation(r, c));
      }
    }
  }
  return out;
}

}  // namespace raytime::python

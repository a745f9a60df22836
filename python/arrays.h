// Conversions between numpy arrays / Python dicts and raytime's types, shared by the bindings.
// Poses are world_from_cam (camera-to-world, OpenCV camera axes: x right, y down, z forward) as
// 4x4 matrices [R c; 0 0 0 1]: R the camera's axes in the world, c its centre.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>

#include <string>
#include <vector>

#include "core/camera.h"
#include "core/named_enum.h"
#include "core/types.h"

namespace raytime::python {

using PoseArray = pybind11::array_t<double, pybind11::array::c_style | pybind11::array::forcecast>;

// Pixel conventions of the arrays and camera dicts a caller gives: OpenCV's (the centre of the
// top-left pixel at (0, 0), raytime's own) or COLMAP's (at (0.5, 0.5): pycolmap's cameras and
// keypoints).
enum class PixelConvention { kOpenCv, kColmap };
constexpr std::array<EnumName<PixelConvention>, 2> EnumNames(PixelConvention) {
  return {{{PixelConvention::kOpenCv, "opencv"}, {PixelConvention::kColmap, "colmap"}}};
}
PixelConvention PixelConventionFromName(const std::string& name);

// {"model": COLMAP model name, "width", "height", "params": in COLMAP's order} as intrinsics.
// InputError naming `where` on a missing key or a model raytime does not read.
CameraIntrinsics CameraFromDict(const pybind11::dict& camera, PixelConvention convention,
                                const std::string& where);
// The intrinsics as such a dict (model PINHOLE, or OPENCV with distortion).
pybind11::dict CameraToDict(const CameraIntrinsics& camera, PixelConvention convention);

// An (N, 4, 4) array as N poses; InputError on another shape, a last row other than 0 0 0 1 or a
// block that is not a rotation (named by index).
std::vector<Rigid3> PosesFromArray(const PoseArray& poses, const std::string& what);
// N poses as an (N, 4, 4) array.
PoseArray PosesToArray(const std::vector<Rigid3>& poses);

}  // namespace raytime::python

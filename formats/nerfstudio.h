// nerfstudio / instant-ngp `transforms.json`: per-frame camera-to-world 4x4 matrices in OpenGL
// camera axes (x right, y up, z backwards), intrinsics shared at the top level or per frame, read
// as nerfstudio's dataparser reads them: a top-level value is every frame's (a frame's own is
// ignored), distortion (k1..p2 or distortion_params [k1, k2, k3, k4, p1, p2]) one group.
//
// Conversions: R_opencv = R_opengl * diag(1, -1, -1). nerfstudio's cx, cy follow COLMAP's pixel
// convention (pixel centres at +0.5), so 0.5 is subtracted on reading and added on writing.
// An image's name is its `file_path` with a leading "./" and the directory common to all frames
// (typically "images/") removed; that directory, relative to the JSON file, is the image root.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "core/types.h"

namespace raytime {

// Errors name the file, the frame index and what was expected (e.g. a 3x3 transform_matrix).
void ReadTransformsJson(const std::string& path, ImageSet* images, PoseSet* poses);

// Writes shared intrinsics at the top level when every image uses the same camera, per-frame
// otherwise. `image_prefix` is prepended to names in file_path (default "images/"). Images
// without a pose are left out; a pose without an image is an InputError. `extra_fields` are added
// at the top level (e.g. ply_file_path, train_filenames, test_filenames), `frame_fields[name]` to
// that image's frame (trainers ignore keys they do not know). Atomic.
void WriteTransformsJson(const std::string& path, const ImageSet& images, const PoseSet& poses,
                         const std::string& image_prefix = "images/",
                         const nlohmann::json& extra_fields = nlohmann::json::object(),
                         const nlohmann::json& frame_fields = nlohmann::json::object());

}  // namespace raytime

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
#include <vector>

#include "core/types.h"

namespace raytime {

// One frame of a transforms.json as read: its image name, camera and camera-to-world pose (OpenCV
// axes, the file's world).
struct TransformsFrame {
  std::string name;
  CameraIntrinsics camera;
  Rigid3 world_from_cam;
};

struct TransformsFrames {
  std::vector<TransformsFrame> frames;  // in the file's order
  std::string common_directory;         // of every file_path ("images/"), removed from the names
};

// The document of `text`, read from `path` (for messages): an object with a non-empty "frames"
// array, else an InputError.
nlohmann::json ParseTransformsJson(const std::string& path, const std::string& text);

// Every frame of a parsed document, read as ReadTransformsJson reads them; InputError naming the
// frame when one is malformed or two name the same image.
TransformsFrames ReadTransformsFrames(const std::string& path, const nlohmann::json& top);

// A pose as nerfstudio's transform_matrix: camera-to-world in OpenGL axes, rows, last 0 0 0 1.
nlohmann::json TransformMatrixJson(const Rigid3& world_from_cam);

// A camera as nerfstudio's keys: w, h, fl_x, fl_y, cx, cy (its pixel convention), k1, k2, p1, p2.
nlohmann::json TransformsIntrinsicsJson(const CameraIntrinsics& intrinsics);

// Errors name the file, the frame index and what was expected (e.g. a 3x3 transform_matrix).
// `text`, when given, receives the file's text as read (to write it back changed:
// formats/nerfstudio_folder.h).
void ReadTransformsJson(const std::string& path, ImageSet* images, PoseSet* poses,
                        std::string* text = nullptr);

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

// COLMAP sparse models, text and binary (cameras, images, points3D), as COLMAP 3.8 writes them.
//
// COLMAP's pixel convention puts the centre of the top-left pixel at (0.5, 0.5); raytime's is
// OpenCV's (0, 0). The raw ColmapModel structs hold COLMAP's numbers unchanged; the conversions
// to and from raytime types add or subtract 0.5 on principal points and keypoints (SPEC §2).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "core/types.h"

namespace raytime {

struct ColmapCamera {
  uint32_t camera_id = 0;
  std::string model;  // "PINHOLE", "OPENCV", "SIMPLE_RADIAL", ...
  uint64_t width = 0;
  uint64_t height = 0;
  std::vector<double> params;  // in COLMAP's order and pixel convention
};

struct ColmapImage {
  uint32_t image_id = 0;
  std::string name;
  uint32_t camera_id = 0;
  Rigid3 cam_from_world;                  // COLMAP stores world-to-camera (qvec, tvec)
  std::vector<Eigen::Vector2d> points2D;  // COLMAP pixel convention
  std::vector<uint64_t> point3D_ids;      // kInvalidPoint3DId where not triangulated
};

constexpr uint64_t kInvalidPoint3DId = std::numeric_limits<uint64_t>::max();

struct ColmapTrackElement {
  uint32_t image_id = 0;
  uint32_t point2D_idx = 0;
};

struct ColmapPoint3D {
  uint64_t point3D_id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  uint8_t rgb[3] = {0, 0, 0};
  double error = 0.0;
  std::vector<ColmapTrackElement> track;
};

struct ColmapModel {
  std::map<uint32_t, ColmapCamera> cameras;
  std::map<uint32_t, ColmapImage> images;
  std::map<uint64_t, ColmapPoint3D> points3D;
};

// Reads a model folder; the binary files (cameras.bin, ...) are preferred when both exist.
// Errors name the file and (text) the line and what was expected.
ColmapModel ReadColmapModel(const std::string& dir);
ColmapModel ReadColmapModelText(const std::string& dir);
ColmapModel ReadColmapModelBinary(const std::string& dir);
// Writers are atomic per folder; rotations are written as unit quaternions with 17 significant
// digits so a text round trip preserves poses to 1e-9.
void WriteColmapModelText(const ColmapModel& model, const std::string& dir);
// Whether COLMAP's text model holds image `name` as it is: its reader splits lines on spaces, so a
// name that is empty or has whitespace would not survive (the binary model keeps it).
bool ColmapTextHoldsName(const std::string& name);
void WriteColmapModelBinary(const ColmapModel& model, const std::string& dir);

// COLMAP camera -> raytime intrinsics. Supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL,
// RADIAL, OPENCV (k1, k2, p1, p2). Others raise InputError naming the model.
CameraIntrinsics IntrinsicsFromColmap(const ColmapCamera& camera);
// raytime intrinsics -> PINHOLE when distortion is zero, OPENCV otherwise.
ColmapCamera ColmapFromIntrinsics(const CameraIntrinsics& intrinsics, uint32_t camera_id);

// Images, intrinsics and poses of a model. Image ids are not kept: names are the join key.
void FromColmapModel(const ColmapModel& model, ImageSet* images, PoseSet* poses);
// A model with one camera per ImageSet camera and the poses of the named images (images
// without a pose are left out; a pose without an image is an InputError). Image ids are 1-based
// positions in `images` so they agree with a database exported from the same ImageSet; points3D is
// empty.
ColmapModel ToColmapModel(const ImageSet& images, const PoseSet& poses);

}  // namespace raytime

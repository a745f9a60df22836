// What the phone-capture and dataset readers (record3d, polycam, scanner3d, nerfcapture,
// mobilebrick, scannetpp_iphone, arkitscenes, lamar; docs/formats.md) have in common: each turns
// its files into a CaptureRecording (frames with the app's pose, optionally ground truth, a 3x3 K
// and a timestamp), and one function makes the dataset from it, checking every image's real size
// against the intrinsics.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/geometry.h"
#include "core/types.h"
#include "core/warnings.h"
#include "formats/dataset.h"

namespace raytime {

// ARKit's (and OpenGL's) camera axes are x right, y up, z backward; raytime's (OpenCV's) are
// x right, y down, z forward. A camera-to-world rotation converts by right-multiplying with this
// matrix, which is its own inverse.
const Eigen::Matrix3d& ArkitFromOpenCvAxes();

// ARKit's intrinsics (`ARCamera.intrinsics`) in raytime's pixel convention. Apple documents the
// principal point as "the offsets of the principal point from the top-left corner of the image
// frame": measured from the image's corner, where the top-left pixel's centre is at (0.5, 0.5)
// (COLMAP's convention, as LaMAR's scantools reads them), so 0.5 is subtracted from cx and cy.
Eigen::Matrix3d FromArkitIntrinsics(const Eigen::Matrix3d& K);

struct CaptureFrame {
  std::string name;       // image name relative to the recording's image root; the join key
  std::string source;     // the file this frame's values came from (for errors)
  bool has_image = true;  // false: the file holds a pose for a frame whose image was not kept
  std::optional<Rigid3> capture;       // the app's own pose (raytime axes): the prior
  std::optional<Rigid3> ground_truth;  // the dataset's reference pose, where it has one
  std::optional<Eigen::Matrix3d> K;    // 3x3 intrinsics [fx s cx; 0 fy cy; 0 0 1]
  int width = 0, height = 0;     // the size K refers to; 0 = not in the file (the image's own)
  std::optional<double> time_s;  // on the capture's clock
};

struct CaptureRecording {
  std::string format;      // "record3d", ...
  std::string image_root;  // folder the frame names are relative to
  std::vector<CaptureFrame> frames;
  std::vector<std::string> files;  // metadata files read (for content hashes)
  Warnings warnings;
};

// A JSON file as a value; InputError naming the file when it does not parse.
nlohmann::json ReadJsonFile(const std::string& path);

// `key` of a JSON object as a finite number / an array of exactly `count` finite numbers
// (count < 0: any length). InputError naming `path`, `where` (e.g. "frame 3") and what was
// expected.
double JsonNumber(const nlohmann::json& object, const std::string& key, const std::string& path,
                  const std::string& where);
std::vector<double> JsonNumbers(const nlohmann::json& object, const std::string& key, int count,
                                const std::string& path, const std::string& where);

// A width or height read from a file: a whole number of pixels from 1 to 1e9 (what an int holds,
// with room). InputError naming `path`, `line` (0: none) and `what` (e.g. "\"w\"") otherwise.
int PixelSize(double value, const std::string& path, int line, const std::string& what);

// Every whitespace-separated number of a text file, in order (a 3x3 or 4x4 matrix file, a .pincam
// line). InputError naming the file and line of a token that is not a finite number.
std::vector<double> ReadNumbersFile(const std::string& path);

// The pose of a camera-to-world rotation in ARKit camera axes and a camera centre, in raytime's
// convention. The rotation is orthonormalized (files hold floats); a matrix that is not a rotation
// within kRotationMatrixTolerance (RotationMatrixProblem) is an InputError naming `path` and
// `where`.
Rigid3 PoseFromArkitCameraToWorld(const Eigen::Matrix3d& world_from_arkit_cam,
                                  const Eigen::Vector3d& centre, const std::string& path,
                                  const std::string& where);
// Same for a rotation already in OpenCV camera axes.
Rigid3 PoseFromCameraToWorld(const Eigen::Matrix3d& world_from_cam, const Eigen::Vector3d& centre,
                             const std::string& path, const std::string& where);

// Width and height of a JPEG or PNG as decoders show it (a JPEG's EXIF orientation 5-8 swaps
// them), read from the file's header without decoding. InputError naming the file when it is
// neither or its header is damaged.
struct ImageSize {
  int width = 0;
  int height = 0;
  int exif_orientation = 1;  // a JPEG's EXIF orientation tag, 1 (as stored) when absent
};
// " (its EXIF orientation is N: ...)" for an image a decoder turns, "" otherwise: what a message
// about a size or principal point that does not fit should say.
std::string ExifOrientationNote(const ImageSize& size);
ImageSize ReadImageSize(const std::string& path);

// `K` (at width x height) for an image of new_width x new_height of the same view: focal lengths
// and principal point scaled per axis, pixel centres kept (OpenCV convention: c' = (c + 0.5) s -
// 0.5).
Eigen::Matrix3d ScaleK(const Eigen::Matrix3d& K, int width, int height, int new_width,
                       int new_height);
// The same for a camera's intrinsics (distortion, in normalized coordinates, unchanged).
CameraIntrinsics ScaleCamera(const CameraIntrinsics& camera, int width, int height, int new_width,
                             int new_height);

// InputError at `source` (the file holding the intrinsics) unless `image_path`, of `size`, is the
// width x height view rescaled: the same aspect ratio within 1 %; another is a rotated or cropped
// image, and the message names its EXIF orientation where it has one.
void RequireRescaledView(int width, int height, const ImageSize& size, const std::string& source,
                         const std::string& image_path);

// The dataset of a recording: one image per frame with an image (sizes read from the files;
// intrinsics at another size of the same aspect are rescaled with an "intrinsics_rescaled"
// warning, another aspect or a principal point outside the image is an InputError naming the
// file), the capture poses as `capture` and ground truth as `ground_truth` (each only when some
// frame has one), timestamps, and `num_poses_without_image`. Every frame with an image must have
// a K. Cameras are not merged here (LoadDataset does it for every format).
Dataset DatasetFromRecording(CaptureRecording recording);

// The poses of every frame of a recording, with or without an image: the capture's, or the ground
// truth when the recording has no capture poses (for ReadPoseFile).
PoseSet PosesOfRecording(const CaptureRecording& recording);

}  // namespace raytime

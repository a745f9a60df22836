// Test-only writers of the capture formats (docs/formats.md), so each reader is checked against
// files written by an independent implementation of the documented conventions, from a real
// scene's ground truth perturbed by a known amount. Not in the library: raytime reads these
// formats, it never writes them.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/geometry.h"

namespace raytime::fixtures {

// One frame of a capture: its image file (copied or encoded into the fixture), the pose in
// raytime's convention (world_from_cam, OpenCV camera axes), its K (OpenCV pixel convention) and
// its time on the capture's clock.
struct Frame {
  std::string image;  // source image file
  Rigid3 world_from_cam;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  double time_s = 0;
};

struct Capture {
  int width = 0, height = 0;
  std::vector<Frame> frames;
};

// The sample scene data/sample/fountain-P11 (11 images, 768x512) read with the Strecha reader,
// each pose turned by 2° about a per-frame axis and moved by 5 cm (a known perturbation), each K
// with fx + 0.25 i px and cy - 0.125 i px (per-frame intrinsics), frame i at 100 + i / 10 s.
Capture SampleCapture();

// The known perturbation of SampleCapture (for tests that compare against the ground truth).
Rigid3 Perturb(const Rigid3& world_from_cam, int index);

// Record3D: ROOT/rgb/<i>.jpg and ROOT/metadata.json. `scale` writes the metadata (w, h, K and the
// per-frame coefficients) for images `scale` times the real size.
void WriteRecord3d(const Capture& capture, const std::string& root, double scale = 1.0);

// Polycam raw data: keyframes/corrected_images/<us>.jpg and corrected_cameras/<us>.json with the
// capture's poses, and keyframes/images + cameras with the same images and the poses moved by
// 1 m (raytime must prefer the corrected ones). <us> is the frame time in microseconds.
void WritePolycam(const Capture& capture, const std::string& root);

// 3D Scanner App: frame_NNNNN.json for 3 poses per frame (frame i of the capture is ARKit frame
// 3 i; frames 3 i + 1 and 3 i + 2 lie between it and the next, without an image) and
// frame_NNNNN.jpg for every third.
void WriteScanner3d(const Capture& capture, const std::string& root);
// The name of capture frame i in a WriteScanner3d fixture.
std::string Scanner3dName(int index);

// NeRFCapture: ROOT/transforms.json (file_path "images/<i>" without extension) and
// ROOT/images/<i>.jpg.
void WriteNerfCapture(const Capture& capture, const std::string& root);

// nerfstudio, as `ns-process-data` lays out a folder: ROOT/images/frame_NNNNN.jpg (and
// images_2/ with the same files, standing for its downscaled copies), depths/ and masks/ (one file
// per frame), sparse_pc.ply and ROOT/transforms.json: camera_model, per-frame intrinsics
// (nerfstudio's pixel convention: OpenCV's + 0.5), transform_matrix (camera-to-world, OpenGL axes)
// in the world of `applied_from_world` (written as applied_transform, as ns-process-data writes the
// transform it applied), colmap_im_id, depth_file_path, mask_path, and keys of the user's own per
// frame ("my_tag") and at the top level ("my_note").
void WriteNerfstudio(const Capture& capture, const std::string& root,
                     const Rigid3& applied_from_world);
// The name of capture frame i in a WriteNerfstudio fixture.
std::string NerfstudioName(int index);

// MobileBrick: ROOT/image/NNNNNN.jpg, intrinsic/NNNNNN.txt, pose/NNNNNN.txt (the capture's poses
// written as the ground truth) and, when `arkit_from_world` is given, PoRF's cameras_arkit.npz
// (as np.savez writes it) with world_mat_<i> = K inv(arkit_from_world * pose_i) and a scale_mat.
void WriteMobileBrick(const Capture& capture, const std::string& root,
                      const Rigid3* arkit_from_world = nullptr);

// ScanNet++ iPhone: ROOT/iphone/rgb/frame_NNNNNN.jpg and ROOT/iphone/pose_intrinsic_imu.json with
// the capture's poses as `aligned_pose` and `arkit_from_world` * those poses as `pose` (ARKit's own
// world frame), in ARKit camera axes when `arkit_axes`.
void WriteScanNetPP(const Capture& capture, const std::string& root, const Rigid3& arkit_from_world,
                    bool arkit_axes);

// ARKitScenes raw layout: ROOT/lowres_wide/<video>_<t>.png (the JPEG bytes under a .png name: the
// readers look at the header), lowres_wide_intrinsics/<video>_<t>.pincam and lowres_wide.traj with
// one world-to-camera row at each frame's time and one halfway to the next frame (<t> with 3
// decimals).
void WriteArkitScenes(const Capture& capture, const std::string& root, const std::string& video);
std::string ArkitScenesName(const std::string& video, double time_s);

// LaMAR session: raw_data/cam0/<us>.jpg, sensors.txt (camera cam0, PINHOLE, COLMAP pixel
// convention), rigs.txt (cam0 in rig0 with `rig_from_cam`), trajectories.txt (rig0's poses of
// `arkit_from_world` * the capture's camera poses, at the images' timestamps),
// proc/alignment_trajectories.txt (cam0's poses: the capture's), images.txt (plus one image at a
// timestamp without a pose).
void WriteLamar(const Capture& capture, const std::string& root, const Rigid3& arkit_from_world,
                const Rigid3& rig_from_cam);
std::string LamarName(double time_s);

// Stray Scanner: ROOT/rgb.mp4 (the images as a video at `fps`), camera_matrix.csv (the first
// frame's K at `capture_scale` times the video's size) and odometry.csv at `odometry_hz` from the
// first frame's time to the last's, each pose interpolated (SLERP + linear) between the two
// frames it lies between, its `frame` column the nearest video frame. Returns the odometry rows
// (time and pose) it wrote. `fourcc` is the video codec (OpenCV's VideoWriter::fourcc code:
// "mp4v" MPEG-4 Part 2, "avc1" H.264, as the apps write). false when this OpenCV cannot write
// that codec.
struct OdometryRow {
  double time_s;
  int frame;
  Rigid3 world_from_cam;
};
bool WriteStray(const Capture& capture, const std::string& root, double fps, double odometry_hz,
                double capture_scale, std::vector<OdometryRow>* rows,
                const std::string& fourcc = "mp4v");

}  // namespace raytime::fixtures

// Datasets (images + intrinsics + optional ground truth) and pose files in any supported format,
// so a pipeline can be pointed at other data with `--set dataset.format=... dataset.root=...`.
#pragma once

#include <Eigen/Core>
#include <array>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/named_enum.h"
#include "core/options.h"
#include "core/timestamps.h"
#include "core/types.h"
#include "core/warnings.h"

namespace raytime {

// Every dataset.format (docs/formats.md documents each one's files and conventions).
extern const std::vector<std::string> kDatasetFormats;

// What a nerfstudio transforms.json's poses are.
enum class NerfstudioPoses { kCapture, kGroundTruth };
constexpr std::array<EnumName<NerfstudioPoses>, 2> EnumNames(NerfstudioPoses) {
  return {
      {{NerfstudioPoses::kCapture, "capture"}, {NerfstudioPoses::kGroundTruth, "ground_truth"}}};
}

struct DatasetOptions {
  // "strecha" (ROOT/images + ROOT/gt_dense_cameras), "colmap" (ROOT/images + a sparse model whose
  // poses are the ground truth), "nerfstudio" (ROOT/transforms.json); phone captures whose app
  // poses become pose set "capture": "record3d", "polycam", "stray", "scanner3d", "nerfcapture";
  // the paper's datasets: "mobilebrick", "scannetpp_iphone", "arkitscenes", "lamar".
  std::string format = "strecha";
  std::string root;
  // Image folder relative to root for "colmap" (default "images").
  std::string images = "images";
  // COLMAP model folder relative to root; "" tries sparse/0, sparse, then root itself.
  std::string model;
  // nerfstudio file relative to root.
  std::string transforms = "transforms.json";
  // nerfstudio: what the file's poses are. A folder made by ns-process-data holds the phone's poses
  // (record3d, polycam) or COLMAP's: a capture's poses, the prior to refine; a benchmark's file
  // holds its reference poses.
  NerfstudioPoses nerfstudio_poses = NerfstudioPoses::kCapture;
  // stray (a video): every stride-th frame, or num_frames spread evenly (the front end's
  // VideoFramesOptions rules).
  int stride = 1;
  int num_frames = 0;
  // stray: width of the frames camera_matrix.csv describes; 0 = the decoded frames' own, or a
  // scale estimated from the principal point when it lies far from their centre.
  int capture_width = 0;
  // Frames and poses on separate clocks (stray, arkitscenes, lamar).
  TimestampJoinOptions timestamps;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("format", format, "Dataset layout (docs/formats.md)", OneOf(kDatasetFormats));
    v("root", root, "Dataset folder", NonEmpty());
    v("images", images, "colmap: image folder relative to root");
    v("model", model, "colmap: model folder relative to root; \"\" tries sparse/0, sparse, root");
    v("transforms", transforms, "nerfstudio, nerfcapture: transforms file relative to root");
    v("nerfstudio_poses", nerfstudio_poses,
      "nerfstudio: the file's poses are the capture's (pose set capture, the prior to refine) or "
      "the ground truth (a benchmark's)");
    v("stride", stride, "stray: keep every stride-th video frame (frame 0 first)", Positive(),
      AtMost(1e6));
    v("num_frames", num_frames,
      "stray: video frames spread evenly over the video; overrides stride when > 0", NonNegative(),
      AtMost(1e6));
    v("capture_width", capture_width,
      "stray: width in pixels of the frames camera_matrix.csv describes; 0 = the decoded "
      "video's, or estimated from the principal point when it is far from their centre",
      NonNegative(), AtMost(1e5));
    timestamps.VisitFields(v);  // flat key: dataset.max_time_gap_s
  }
};

// A video whose frames are the dataset's images, still to be decoded (stray): core does not decode
// video, so the caller (the dataset stage) extracts the frames and calls AttachVideoFrames.
struct CaptureVideo {
  std::string path;                                 // the video file
  std::string intrinsics_file;                      // where K came from (for messages)
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  // at the capture's resolution
  // The trajectory on the capture's clock, each pose with the number of the video frame it was
  // recorded with (-1 when unknown).
  std::vector<StampedPose> trajectory;
  std::vector<int> trajectory_frames;
  std::string trajectory_file;  // for messages
};

struct Dataset {
  ImageSet images;
  std::optional<PoseSet> ground_truth;
  // The capture app's own poses (ARKit, ARCore, ...): a coarse prior, written by the dataset stage
  // as pose set "capture" (role prior) for `prior.source: capture`.
  std::optional<PoseSet> capture;
  // Seconds on the capture's clock, per image name, where the format records them.
  std::map<std::string, double> timestamps;
  // Poses the format holds for frames whose image was not kept (3D Scanner App saves every third
  // image): not frames of the dataset, counted for the summary.
  int num_poses_without_image = 0;
  std::optional<CaptureVideo> video;
  std::vector<std::string> files;  // every file the dataset was read from (for content hashes)
  // nerfstudio: the transforms.json read and its text, written back changed by the export
  // (formats/nerfstudio_folder.h); empty for other formats.
  std::string transforms_path;
  std::string transforms_text;
  // What the readers accepted with a doubt (e.g. a negligible skew dropped); the dataset stage
  // reports them in its summary.
  Warnings warnings;
};

// Loads the dataset and checks that every image file exists (InputError naming the first
// missing one and how many are missing). Images are sorted by name. For a video format (stray)
// the images are still to be decoded: `video` is set and `images` empty (AttachVideoFrames).
Dataset LoadDataset(const DatasetOptions& options);

// The formats accepted by ReadPoseFile / WritePoseFile.
extern const std::vector<std::string> kPoseFileFormats;

// Reads the poses of a file or folder: "colmap" (model folder), "nerfstudio" (transforms.json),
// "tum" (trajectory), "strecha" (scene root); a capture app's poses (every pose the files hold,
// also those of frames without an image): "record3d" (export folder or metadata.json),
// "polycam" (export folder), "stray" (export folder or odometry.csv, names frame_NNNNNN.jpg as
// the dataset's video frames), "scanner3d" (export folder), "nerfcapture" (folder or
// transforms.json); the paper's datasets (their capture poses where they have them, else their
// ground truth): "mobilebrick" (sequence folder: the ARKit poses of cameras_arkit.npz, else the
// ground truth), "scannetpp_iphone" (scene
// folder: the ARKit poses), "arkitscenes" (video folder: ground truth, frames joined by time),
// "lamar" (session folder: the device's tracking).
// `images`, when given, supplies the names for TUM rows (in name order). Names are not joined here:
// the caller decides what a pose without an image, or an image without a pose, means (JoinNames).
PoseSet ReadPoseFile(const std::string& format, const std::string& path,
                     const ImageSet* images = nullptr);

// ReadPoseFile, or for format "hdf5" a pose set of a raytime HDF5 file: `pose_set`, or the only
// one there; with several and none named, an InputError ending "choose one `choose`" (how the
// caller names a set: "with --est-set/--gt-set", "(pose_set=)").
PoseSet ReadPoseFileOrSet(const std::string& format, const std::string& path,
                          const std::string& pose_set, const std::string& choose);

}  // namespace raytime

// Datasets (images + intrinsics + optional ground truth) and pose files in any supported format,
// so a pipeline can be pointed at other data with `--set dataset.format=... dataset.root=...`.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/options.h"
#include "core/types.h"
#include "core/warnings.h"

namespace raytime {

struct DatasetOptions {
  // "strecha" (ROOT/images + ROOT/gt_dense_cameras), "colmap" (ROOT/images + a sparse model whose
  // poses are the ground truth) or "nerfstudio" (ROOT/transforms.json).
  std::string format = "strecha";
  std::string root;
  // Image folder relative to root for "colmap" (default "images").
  std::string images = "images";
  // COLMAP model folder relative to root; "" tries sparse/0, sparse, then root itself.
  std::string model;
  // nerfstudio file relative to root.
  std::string transforms = "transforms.json";

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("format", format, "Dataset layout", OneOf({"strecha", "colmap", "nerfstudio"}));
    v("root", root, "Dataset folder", NonEmpty());
    v("images", images, "colmap: image folder relative to root");
    v("model", model, "colmap: model folder relative to root; \"\" tries sparse/0, sparse, root");
    v("transforms", transforms, "nerfstudio: transforms file relative to root");
  }
};

struct Dataset {
  ImageSet images;
  std::optional<PoseSet> ground_truth;
  std::vector<std::string> files;  // every file the dataset was read from (for content hashes)
  // What the readers accepted with a doubt (e.g. a negligible skew dropped); the dataset stage
  // reports them in its summary.
  Warnings warnings;
};

// Loads the dataset and checks that every image file exists (InputError naming the first
// missing one and how many are missing). Images are sorted by name.
Dataset LoadDataset(const DatasetOptions& options);

// The formats accepted by ReadPoseFile / WritePoseFile.
extern const std::vector<std::string> kPoseFileFormats;

// Reads the poses of a file or folder: "colmap" (model folder), "nerfstudio" (transforms.json),
// "tum" (trajectory), "strecha" (scene root). `images`, when given, supplies the names for TUM
// rows (in name order). Names are not joined here: the caller decides what a pose without an
// image, or an image without a pose, means (JoinNames).
PoseSet ReadPoseFile(const std::string& format, const std::string& path,
                     const ImageSet* images = nullptr);

}  // namespace raytime

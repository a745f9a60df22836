// The HDF5 intermediate files that stages exchange (schema documented in docs/hdf5_schema.md).
//
// Every file carries root attributes `schema = "raytime"` and `schema_version`. A stage writes one
// file; writers are atomic (temporary file + rename on Commit), so a failed stage leaves nothing
// under the final name. Readers check the schema name and version and turn HDF5's failures on a
// truncated or foreign file into an InputError that names the file.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/types.h"

namespace raytime {

constexpr int kHdf5SchemaVersion = 1;

// Who wrote a group, with which options, when (SPEC: provenance attributes).
struct Provenance {
  std::string stage;           // e.g. "prior", "refine"
  nlohmann::json options;      // the stage's options as written by OptionsToJson
  std::string created_utc;     // ISO 8601, filled by the writer when empty
  std::string raytime_version; // filled by the writer when empty
};

// Keypoints of one image, OpenCV pixel convention (SPEC §2).
struct ImageFeatures {
  // Rows: x, y (pixels), scale (pixels), orientation (radians).
  Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor> keypoints;
  // Rows: one descriptor per keypoint (SIFT: 128 columns, uint8 after RootSIFT quantization).
  Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> descriptors;
};

// Configuration of a verified two-view geometry, numbered as COLMAP's TwoViewGeometry so that the
// database export is a plain copy.
enum class TwoViewConfig : int {
  kUndefined = 0,
  kDegenerate = 1,
  kCalibrated = 2,
  kUncalibrated = 3,
  kPlanar = 4,
  kPanoramic = 5,
  kPlanarOrPanoramic = 6,
  kWatermark = 7,
  kMultiple = 8,
};

struct TwoViewGeometry {
  TwoViewConfig config = TwoViewConfig::kUndefined;
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  // Relative pose cam2_from_cam1 when known (identity otherwise).
  Rigid3 cam2_from_cam1;
  // Rows: keypoint index in image 1, keypoint index in image 2.
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> inlier_matches;
};

// Putative matches and the verified geometry of one image pair (image1 < image2, indices into
// the file's image list).
struct PairMatches {
  int image1 = 0;
  int image2 = 0;
  Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor> matches;
  TwoViewGeometry geometry;
};

class Hdf5Writer {
 public:
  // Creates the temporary file next to `path`; nothing appears under `path` before Commit().
  explicit Hdf5Writer(const std::string& path);
  ~Hdf5Writer();  // removes the temporary file unless committed
  Hdf5Writer(const Hdf5Writer&) = delete;
  Hdf5Writer& operator=(const Hdf5Writer&) = delete;

  void WriteImages(const ImageSet& images);
  // Group /poses/<name>; `name` is typically the role ("prior", "refined", "ground_truth").
  void WritePoseSet(const std::string& name, const PoseSet& poses, PoseRole role,
                    const Provenance& provenance);
  // features[i] belongs to image i of the image list written with WriteImages.
  void WriteFeatures(const std::vector<ImageFeatures>& features, const Provenance& provenance);
  void WriteMatches(const std::vector<PairMatches>& pairs, const Provenance& provenance);
  // Free-form JSON document (stage summaries, metrics) stored as a string dataset /json/<name>.
  void WriteJson(const std::string& name, const nlohmann::json& value);

  // Closes the file and renames it onto the final path.
  void Commit();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class Hdf5Reader {
 public:
  // Throws InputError (naming `path`) for a missing, truncated or non-raytime file and for a
  // schema version this build cannot read.
  explicit Hdf5Reader(const std::string& path);
  ~Hdf5Reader();
  Hdf5Reader(const Hdf5Reader&) = delete;
  Hdf5Reader& operator=(const Hdf5Reader&) = delete;

  const std::string& path() const;
  int schema_version() const;

  bool HasImages() const;
  ImageSet ReadImages() const;

  std::vector<std::string> PoseSetNames() const;
  bool HasPoseSet(const std::string& name) const;
  PoseSet ReadPoseSet(const std::string& name, PoseRole* role = nullptr,
                      Provenance* provenance = nullptr) const;

  bool HasFeatures() const;
  std::vector<ImageFeatures> ReadFeatures(Provenance* provenance = nullptr) const;

  bool HasMatches() const;
  std::vector<PairMatches> ReadMatches(Provenance* provenance = nullptr) const;

  bool HasJson(const std::string& name) const;
  nlohmann::json ReadJson(const std::string& name) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace raytime

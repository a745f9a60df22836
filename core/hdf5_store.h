// The HDF5 intermediate files that stages exchange (schema documented in docs/hdf5_schema.md).
//
// Every file carries root attributes `schema = "raytime"` and `schema_version`. A stage writes one
// file; writers are atomic (temporary file + rename on Commit), so a failed stage leaves nothing
// under the final name. Readers check the schema name and version and turn HDF5's failures on a
// truncated or foreign file into an InputError that names the file.
//
// This is raytime's schema (groups, datasets, versions); hdf5_io.h holds the generic HDF5 calls
// it is written with.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/features.h"
#include "core/provenance.h"
#include "core/types.h"

namespace raytime {

constexpr int kHdf5SchemaVersion = 1;

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
  // Group /ray_times/<pose_set>: a ray-time solve's observations beside the pose set it solved
  // for. Throws std::invalid_argument on inconsistent sizes or indices out of range.
  void WriteRayTimes(const std::string& pose_set, const RayTimeObservations& rays);
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

  bool HasRayTimes(const std::string& pose_set) const;
  // Fails (InputError naming the file) on inconsistent sizes, indices out of range or a ray time
  // that is neither positive nor NaN.
  RayTimeObservations ReadRayTimes(const std::string& pose_set) const;

  bool HasJson(const std::string& name) const;
  nlohmann::json ReadJson(const std::string& name) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace raytime

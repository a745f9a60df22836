// Shared data types passed between stages (through HDF5 files) and file formats.
// Image names are the join key between images, priors and ground truth (SPEC §2).
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"
#include "core/named_enum.h"

namespace raytime {

struct ImageInfo {
  std::string name;      // relative path below the image root, e.g. "0000.jpg"; the join key
  int width = 0;         // pixels
  int height = 0;        // pixels
  int camera_index = 0;  // index into ImageSet::cameras
};

// The images of a scene and their intrinsics. Most captures share one camera.
struct ImageSet {
  std::string image_root;                 // folder the names are relative to ("" if unknown)
  std::vector<ImageInfo> images;          // sorted by name
  std::vector<CameraIntrinsics> cameras;  // at least one

  // Index of an image by name, or -1.
  int Find(const std::string& name) const;
};

// Role of a pose set, written into provenance attributes.
enum class PoseRole { kGroundTruth, kPrior, kRefined };
constexpr std::array<EnumName<PoseRole>, 3> EnumNames(PoseRole) {
  return {{{PoseRole::kGroundTruth, "ground_truth"},
           {PoseRole::kPrior, "prior"},
           {PoseRole::kRefined, "refined"}}};
}
inline const char* PoseRoleName(PoseRole role) { return NameOf(role); }
PoseRole PoseRoleFromName(const std::string& name);  // throws InputError on an unknown name

// One pose per named image. Missing poses are absent from the map: a pose set may cover a
// subset of the images (a reconstruction that did not register every image).
struct PoseSet {
  std::map<std::string, Rigid3> world_from_cam;  // keyed by image name

  size_t size() const { return world_from_cam.size(); }
  bool Has(const std::string& name) const { return world_from_cam.count(name) > 0; }
};

// Result of joining two name-keyed collections: the names in both, and those in only one.
struct NameJoin {
  std::vector<std::string> both;
  std::vector<std::string> only_left;
  std::vector<std::string> only_right;
  bool Complete() const { return only_left.empty() && only_right.empty(); }
  // "3 names only in <left>: a.jpg, b.jpg, ...; 1 name only in <right>: ..." (first few names).
  std::string Describe(const std::string& left, const std::string& right) const;
};

NameJoin JoinNames(const std::vector<std::string>& left, const std::vector<std::string>& right);
std::vector<std::string> Names(const PoseSet& poses);
std::vector<std::string> Names(const ImageSet& images);

// Capture order of image names, natural name order: runs of digits compare as numbers ("frame2" <
// "frame10"), the rest as text; equal numbers with different padding fall back to plain text order.
bool NaturalNameLess(const std::string& a, const std::string& b);

}  // namespace raytime

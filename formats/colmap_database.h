// COLMAP 3.8 feature databases (`database.db`, SQLite): import into raytime's images, features
// and matches, and export ours, so that users' existing databases feed raytime and COLMAP's
// `point_triangulator` and `mapper` (the classical control) run on exactly our matches (SPEC §5,
// paper §4.1 "Classical control").
//
// What changes at the boundary:
// - Pixels: COLMAP puts the centre of the top-left pixel at (0.5, 0.5), raytime at (0, 0)
//   (SPEC §2). Keypoints and principal points move by 0.5; F and H, which act on pixel
//   coordinates, are conjugated by the same shift; E (normalized coordinates) is unchanged. The
//   shift is computed in double and rounded once to float32, so a keypoint coordinate comes back
//   bit-exact unless x + 0.5 needs more float32 precision than x (x below 1 px, or within 0.5 px
//   under a power of two), where it differs by at most one float32 ulp (6e-5 px at 1000 px).
// - Image ids: exported ids are 1-based positions in the name-sorted ImageSet and camera ids are
//   camera_index + 1, as in ToColmapModel, so a prior written with ToColmapModel joins the
//   database. Imported ids are dropped: images are sorted by name and pairs re-indexed (a pair
//   whose COLMAP ids run against name order is swapped: matches columns, F^T, E^T, H^-1 and the
//   inverse relative pose).
// - Keypoints: COLMAP stores float32 rows of 2 (x, y), 4 (x, y, scale, orientation) or 6 (x, y,
//   affine shape a11 a12 a21 a22) columns. Import derives scale and orientation from the shape
//   as COLMAP does; export writes 4 columns, which COLMAP 3.8 reads and which keeps scale and
//   orientation exact.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/features.h"
#include "core/types.h"
#include "formats/colmap_model.h"

namespace raytime {

// COLMAP's pair id: image_id1 * kColmapMaxNumImages + image_id2 with image_id1 < image_id2.
constexpr uint64_t kColmapMaxNumImages = 2147483647;
uint64_t ColmapPairId(uint32_t image_id1, uint32_t image_id2);
void ColmapImageIdsFromPairId(uint64_t pair_id, uint32_t* image_id1, uint32_t* image_id2);

// The contents of a database in raytime's types.
struct ColmapDatabase {
  ImageSet images;                      // sorted by name; image_root "" (a database has none)
  std::vector<ImageFeatures> features;  // features[i] belongs to images.images[i]
  // Pairs present in the `matches` or the `two_view_geometries` table, sorted by (image1,
  // image2): `matches` from the former, `geometry` (config, F, E, H, relative pose, inliers)
  // from the latter; a relative pose COLMAP did not estimate (zero quaternion) reads as identity.
  std::vector<PairMatches> pairs;
};

// Reads a COLMAP database. InputError naming the file (and table and image or pair) for a
// missing file, a file that is not SQLite, a database without COLMAP's tables, and corrupt
// contents (blob sizes that disagree with rows x cols, indices out of range, unsupported camera
// models, duplicate names).
ColmapDatabase ReadColmapDatabase(const std::string& path);

// Writes a new database with COLMAP 3.8's schema (atomically: temporary file, then rename; an
// existing file at `path` is replaced). `camera_model` is "" (PINHOLE, or OPENCV when the
// intrinsics have distortion: ColmapFromIntrinsics), "PINHOLE" or "OPENCV" (the room protocol's
// refinable distortion, paper §4.3 "Room-scale refinement on ScanNet++"). InputError when the
// features or pairs do not fit the images (counts, indices, keypoints per descriptor).
void WriteColmapDatabase(const std::string& path, const ImageSet& images,
                         const std::vector<ImageFeatures>& features,
                         const std::vector<PairMatches>& pairs,
                         const std::string& camera_model = "");

// ColmapFromIntrinsics with the model chosen as above; InputError for PINHOLE with distortion or
// another model name.
ColmapCamera ColmapCameraWithModel(const CameraIntrinsics& intrinsics, uint32_t camera_id,
                                   const std::string& camera_model);

}  // namespace raytime

// The `colmap_import` stage: features and matches from a user's COLMAP database.db instead of
// raytime's front end (SPEC §5), so an existing COLMAP project feeds every solver arm with its
// own matches. Image names are the join key with the dataset; a name on one side only is an
// error listing the names, never a silent drop.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "formats/colmap_database.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

struct ColmapImportOptions {
  std::string path;  // the COLMAP database.db

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("path", path, "The COLMAP database.db to import", NonEmpty());
  }
};

// Relative difference above which a database camera is reported as disagreeing with the
// dataset's intrinsics (the dataset's are kept: they are what every arm uses).
constexpr double kIntrinsicsTolerance = 1e-3;

class ColmapImportStage : public StageWithOptions<ColmapImportOptions> {
 public:
  std::string type() const override { return "colmap_import"; }
  std::string description() const override {
    return "Import features and matches from a COLMAP database.db";
  }
  std::vector<std::string> Inputs() const override { return {kArtifactImages}; }
  std::vector<std::string> ExternalFiles() const override { return {options_.path}; }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    ColmapDatabase db = ReadColmapDatabase(options_.path);
    const NameJoin join = JoinNames(Names(images), Names(db.images));
    if (!join.Complete()) {
      ThrowInput(options_.path, 0,
                 "image names do not match the dataset: " + join.Describe("dataset", "database"));
    }
    // Both lists are sorted by name and hold the same names, so indices carry over; the checks
    // below make sure the keypoints were measured on images of the dataset's size.
    for (size_t i = 0; i < images.images.size(); ++i) {
      const ImageInfo& ours = images.images[i];
      const ImageInfo& theirs = db.images.images[i];
      if (ours.width != theirs.width || ours.height != theirs.height) {
        ThrowInput(options_.path, 0,
                   "image " + ours.name + " is " + std::to_string(theirs.width) + "x" +
                       std::to_string(theirs.height) + " in the database but " +
                       std::to_string(ours.width) + "x" + std::to_string(ours.height) +
                       " in the dataset (keypoints would be in the wrong pixels)");
      }
      const CameraIntrinsics& a = images.cameras[ours.camera_index];
      const CameraIntrinsics& b = db.images.cameras[theirs.camera_index];
      for (int p = 0; p < kNumIntrinsics; ++p) {
        const double scale = std::max(1.0, std::abs(a.params[p]));
        if (std::abs(a.params[p] - b.params[p]) > kIntrinsicsTolerance * scale) {
          spdlog::warn(
              fmt::format("colmap_import: {}: the database's camera differs from the dataset's "
                          "(parameter {}: {} vs {}); keeping the dataset's",
                          ours.name, p, b.params[p], a.params[p]));
          break;
        }
      }
    }

    size_t num_keypoints = 0, num_matches = 0, num_inliers = 0, num_verified = 0;
    for (const auto& f : db.features) num_keypoints += f.keypoints.rows();
    for (const auto& pair : db.pairs) {
      num_matches += pair.matches.rows();
      num_inliers += pair.geometry.inlier_matches.rows();
      num_verified += pair.geometry.inlier_matches.rows() > 0;
    }
    spdlog::info(
        fmt::format("colmap_import: {} images, {} keypoints, {} pairs ({} verified), {} matches, "
                    "{} inliers from {}",
                    images.images.size(), num_keypoints, db.pairs.size(), num_verified, num_matches,
                    num_inliers, options_.path));
    Hdf5Writer writer(context.output_path);
    writer.WriteFeatures(db.features, MakeProvenance(*this));
    writer.WriteMatches(db.pairs, MakeProvenance(*this));
    writer.Commit();
    return {{"num_images", images.images.size()}, {"num_keypoints", num_keypoints},
            {"num_pairs", db.pairs.size()},       {"num_verified_pairs", num_verified},
            {"num_matches", num_matches},         {"num_inliers", num_inliers}};
  }
};

}  // namespace

std::unique_ptr<Stage> CreateColmapImportStage() { return std::make_unique<ColmapImportStage>(); }

}  // namespace raytime

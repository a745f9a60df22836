// Results are deterministic for a given seed (DEVELOPERS.md, issue 13): two runs of the main job
// with the default number of threads write bit-identical features, matches and refined poses.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "core/hdf5_store.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir.h"

namespace raytime {
namespace {

// Same shape and the same bytes (not merely close: a reduction order that changes with thread
// scheduling shows up in the last bits).
template <typename Matrix>
bool SameBits(const Matrix& a, const Matrix& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(*a.data()) * a.size()) == 0;
}

bool SameBits(const Rigid3& a, const Rigid3& b) {
  return SameBits(a.rotation.coeffs(), b.rotation.coeffs()) &&
         SameBits(a.translation, b.translation);
}

void ExpectSameFeatures(const std::string& a, const std::string& b) {
  const std::vector<ImageFeatures> first = Hdf5Reader(a).ReadFeatures();
  const std::vector<ImageFeatures> second = Hdf5Reader(b).ReadFeatures();
  ASSERT_EQ(first.size(), second.size());
  for (size_t i = 0; i < first.size(); ++i) {
    EXPECT_TRUE(SameBits(first[i].keypoints, second[i].keypoints)) << "keypoints of image " << i;
    EXPECT_TRUE(SameBits(first[i].descriptors, second[i].descriptors))
        << "descriptors of image " << i;
  }
}

void ExpectSameMatches(const std::string& a, const std::string& b) {
  const std::vector<PairMatches> first = Hdf5Reader(a).ReadMatches();
  const std::vector<PairMatches> second = Hdf5Reader(b).ReadMatches();
  ASSERT_EQ(first.size(), second.size());
  for (size_t p = 0; p < first.size(); ++p) {
    const PairMatches& x = first[p];
    const PairMatches& y = second[p];
    const std::string pair = std::to_string(x.image1) + "-" + std::to_string(x.image2);
    ASSERT_TRUE(x.image1 == y.image1 && x.image2 == y.image2) << "pair " << p;
    EXPECT_TRUE(SameBits(x.matches, y.matches)) << "putative matches of " << pair;
    EXPECT_EQ(x.geometry.config, y.geometry.config) << pair;
    EXPECT_TRUE(SameBits(x.geometry.inlier_matches, y.geometry.inlier_matches))
        << "inliers of " << pair;
    EXPECT_TRUE(SameBits(x.geometry.E, y.geometry.E) && SameBits(x.geometry.F, y.geometry.F) &&
                SameBits(x.geometry.cam2_from_cam1, y.geometry.cam2_from_cam1))
        << "geometry of " << pair;
  }
}

void ExpectSamePoses(const std::string& a, const std::string& b, const std::string& name) {
  const PoseSet first = Hdf5Reader(a).ReadPoseSet(name);
  const PoseSet second = Hdf5Reader(b).ReadPoseSet(name);
  ASSERT_EQ(Names(first), Names(second));
  for (const auto& [image, pose] : first.world_from_cam) {
    EXPECT_TRUE(SameBits(pose, second.world_from_cam.at(image))) << name << " pose of " << image;
  }
}

TEST(DeterminismTest, DemoTwiceWithDefaultThreadsIsBitIdentical) {
  TempDir dir("determinism");
  for (const std::string run : {"first", "second"}) {
    const CommandResult result = RunRaytime("run configs/demo.yaml --force --workdir " + dir / run);
    ASSERT_EQ(result.exit_code, 0) << result.output;
  }
  ExpectSameFeatures(dir / "first/features.h5", dir / "second/features.h5");
  ExpectSameMatches(dir / "first/matches.h5", dir / "second/matches.h5");
  ExpectSamePoses(dir / "first/prior.h5", dir / "second/prior.h5", "prior");
  ExpectSamePoses(dir / "first/refine.h5", dir / "second/refine.h5", "refined");
}

}  // namespace
}  // namespace raytime

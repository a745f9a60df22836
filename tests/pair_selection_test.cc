// Prior-guided pair selection (pipelines/pair_selection.h, SPEC §5, issue 10) on synthetic camera
// rings with known answers: the nearest cameras on the ring are chosen, k is respected, the window
// is joined, opposite and far cameras are never paired, images without a pose get window pairs
// only.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "pipelines/pair_selection.h"
#include "testing/random_draws.h"

namespace raytime {
namespace {

using Pairs = std::vector<std::pair<int, int>>;

// A camera at `centre` looking at `target` (y down, roughly along the world's -z).
PairSelectionView ViewLookingAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  PairSelectionView view;
  view.has_pose = true;
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d(0, 0, -1)).normalized();
  const Eigen::Vector3d y = z.cross(x);
  view.world_from_cam_rotation.col(0) = x;
  view.world_from_cam_rotation.col(1) = y;
  view.world_from_cam_rotation.col(2) = z;
  view.centre = centre;
  view.width = 640;
  view.height = 480;
  view.fx = view.fy = 500;  // 65° horizontal field of view
  view.cx = 319.5;
  view.cy = 239.5;
  return view;
}

// `n` cameras on a horizontal circle of radius `radius` around the origin, looking at it, in
// order around the ring: neighbours on the ring are 360/n degrees apart.
std::vector<PairSelectionView> Ring(int n, double radius = 5.0) {
  std::vector<PairSelectionView> views;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    views.push_back(
        ViewLookingAt(radius * Eigen::Vector3d(std::cos(a), std::sin(a), 0), {0, 0, 0}));
  }
  return views;
}

int RingDistance(int i, int j, int n) { return std::min(std::abs(i - j), n - std::abs(i - j)); }

// Every pair (i < j) of an n-ring whose ring distance is at most `d`.
Pairs RingPairs(int n, int d) {
  Pairs pairs;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (RingDistance(i, j, n) <= d) pairs.emplace_back(i, j);
    }
  }
  return pairs;
}

TEST(PairSelection, OverlapIsSymmetricAndFallsWithAngle) {
  const std::vector<PairSelectionView> ring = Ring(24);
  EXPECT_NEAR(ViewOverlap(ring[0], 5, ring[0], 5, 4, 75), 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(ViewOverlap(ring[0], 5, ring[3], 5, 4, 75),
                   ViewOverlap(ring[3], 5, ring[0], 5, 4, 75));
  double previous = 1.0;
  for (int step = 1; step <= 4; ++step) {
    const double overlap = ViewOverlap(ring[0], 5, ring[step], 5, 4, 75);
    EXPECT_LT(overlap, previous) << "step " << step;
    EXPECT_GT(overlap, 0.0) << "step " << step;
    previous = overlap;
  }
  // A camera looking away from the object sees none of it.
  const PairSelectionView away = ViewLookingAt({0, 0, 20}, {0, 0, 40});
  EXPECT_EQ(ViewOverlap(ring[0], 5, away, 5, 4, 75), 0.0);
}

TEST(PairSelection, AutoSceneDepthIsTheRingRadius) {
  std::string source;
  const std::vector<double> depths = SceneDepths(Ring(24, 3.0), 0.0, &source);
  EXPECT_EQ(source, "axes");
  for (double depth : depths) EXPECT_NEAR(depth, 3.0, 1e-9);
  EXPECT_EQ(SceneDepths(Ring(4), 2.5, &source), std::vector<double>(4, 2.5));
  EXPECT_EQ(source, "given");
}

TEST(PairSelection, ParallelAxesFallBackToTheCaptureExtent) {
  // A sideways sweep: cameras on a line, all looking the same way (no converging axes).
  std::vector<PairSelectionView> line;
  for (int i = 0; i < 5; ++i) line.push_back(ViewLookingAt({i - 2.0, 0, 0}, {i - 2.0, 10, 0}));
  std::string source;
  const std::vector<double> depths = SceneDepths(line, 0.0, &source);
  EXPECT_EQ(source, "extent");
  for (double depth : depths) EXPECT_NEAR(depth, 1.0, 1e-9);  // median |x - 0| of -2..2
}

TEST(PairSelection, RingNeighboursAreChosenAndKIsRespected) {
  const int n = 24;
  for (const int k : {2, 4}) {
    PriorPairOptions options;
    options.prior_neighbors = k;
    PairSelectionSummary summary;
    const Pairs pairs = SelectPriorPairs(Ring(n), options, &summary);
    // Each camera's k best are its k nearest on the ring (k / 2 on either side); on a symmetric
    // ring the union adds nothing.
    EXPECT_EQ(pairs, RingPairs(n, k / 2)) << "k " << k;
    EXPECT_EQ(summary.num_pairs, n * k / 2);
    EXPECT_EQ(summary.num_exhaustive_pairs, n * (n - 1) / 2);
    EXPECT_EQ(summary.min_partners, k);
    EXPECT_EQ(summary.max_partners, k);
    EXPECT_TRUE(summary.unpaired_images.empty());
    EXPECT_EQ(summary.num_window_pairs, 0);
  }
}

TEST(PairSelection, KBoundsEachImagesOwnChoiceOnAnIrregularRing) {
  // Uneven spacing: an image may be chosen by more than k others (the union is symmetric), but
  // each image chooses at most k, so the pair count is at most n k.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  std::vector<PairSelectionView> views;
  const int n = 40;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * (i + jitter(rng)) / n;
    views.push_back(ViewLookingAt(5 * Eigen::Vector3d(std::cos(a), std::sin(a), 0), {0, 0, 0}));
  }
  PriorPairOptions options;
  options.prior_neighbors = 3;
  const Pairs pairs = SelectPriorPairs(views, options, nullptr);
  EXPECT_LE(pairs.size(), size_t(n * 3));
  EXPECT_GE(pairs.size(), size_t(n * 3 / 2));
  for (const auto& [i, j] : pairs) EXPECT_LE(RingDistance(i, j, n), 3) << i << "-" << j;
}

TEST(PairSelection, OppositeAndFarCamerasAreNeverPaired) {
  const int n = 20;  // 18° apart: ring distance 4 is 72°, 5 is 90° (beyond the 75° gate)
  std::vector<PairSelectionView> views = Ring(n);
  // Camera 20 looks at the object from 10x the distance, behind camera 0: it sees the object at a
  // tenth of the resolution.
  views.push_back(ViewLookingAt(views[0].centre * 10.0, {0, 0, 0}));
  PriorPairOptions options;
  options.prior_neighbors = n;  // everything that passes the gates
  options.prior_min_overlap = 0;
  options.prior_scene_depth = 5.0;
  const Pairs pairs = SelectPriorPairs(views, options, nullptr);
  std::set<std::pair<int, int>> chosen(pairs.begin(), pairs.end());
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const bool within_angle = RingDistance(i, j, n) <= 4;
      EXPECT_EQ(chosen.count({i, j}) > 0, within_angle) << i << "-" << j;
    }
    EXPECT_EQ(chosen.count({i, n}), 0u) << "far camera paired with " << i;
  }
  // With scale changes allowed, the far camera pairs with the cameras it sees.
  options.prior_max_scale_ratio = 20;
  const Pairs loose = SelectPriorPairs(views, options, nullptr);
  EXPECT_TRUE(std::find(loose.begin(), loose.end(), std::make_pair(0, n)) != loose.end());
}

TEST(PairSelection, WindowIsJoinedInNameOrder) {
  const int n = 12;
  PriorPairOptions options;
  options.prior_neighbors = 2;  // ring distance 1 (wraps around: 0-11)
  options.prior_window = 3;     // name order: i with i+1..i+3, no wrap
  PairSelectionSummary summary;
  const Pairs pairs = SelectPriorPairs(Ring(n), options, &summary);
  std::set<std::pair<int, int>> expected;
  for (const auto& p : RingPairs(n, 1)) expected.insert(p);
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j <= std::min(n - 1, i + 3); ++j) expected.insert({i, j});
  }
  EXPECT_EQ(pairs, Pairs(expected.begin(), expected.end()));
  EXPECT_EQ(summary.num_overlap_pairs, n);
  EXPECT_EQ(summary.num_window_pairs, static_cast<int64_t>(expected.size()) - n);
}

TEST(PairSelection, NaturalNameOrderComparesDigitRunsAsNumbers) {
  EXPECT_TRUE(NaturalNameLess("2.jpg", "10.jpg"));
  EXPECT_FALSE(NaturalNameLess("10.jpg", "2.jpg"));
  EXPECT_TRUE(NaturalNameLess("frame_9.png", "frame_10.png"));
  EXPECT_TRUE(NaturalNameLess("a99999999999999999999999.jpg", "a100000000000000000000000.jpg"));
  EXPECT_TRUE(NaturalNameLess("b1.jpg", "c0.jpg"));
  EXPECT_FALSE(NaturalNameLess("3.jpg", "3.jpg"));
  // Same number, other padding: a strict order all the same (text order).
  EXPECT_NE(NaturalNameLess("01.jpg", "1.jpg"), NaturalNameLess("1.jpg", "01.jpg"));
}

TEST(PairSelection, WindowFollowsCaptureOrderOfUnpaddedFrameNames) {
  // Record3D names frames 0.jpg ... N.jpg: the image list (sorted as text) holds 0, 1, 10, 11,
  // 2, ...; the window must pair 1 with 2, never 1 with 10.
  ImageSet images;
  images.cameras.resize(1);
  const int n = 12;
  std::vector<std::string> names;
  for (int i = 0; i < n; ++i) names.push_back(std::to_string(i) + ".jpg");
  std::sort(names.begin(), names.end());
  for (const auto& name : names) images.images.push_back({name, 0, 0, 0});
  const std::vector<PairSelectionView> views = PairSelectionViews(images, PoseSet());
  PriorPairOptions options;
  options.prior_window = 1;
  PairSelectionSummary summary;
  const Pairs pairs = SelectPriorPairs(views, options, &summary);
  std::set<std::pair<std::string, std::string>> named;
  for (const auto& [i, j] : pairs) named.insert({names[i], names[j]});
  std::set<std::pair<std::string, std::string>> expected;
  for (int k = 0; k + 1 < n; ++k) {
    std::string a = std::to_string(k) + ".jpg", b = std::to_string(k + 1) + ".jpg";
    expected.insert({std::min(a, b), std::max(a, b)});
  }
  EXPECT_EQ(named, expected);
}

TEST(PairSelection, ImagesWithoutAPoseArePairedByTheWindowOnly) {
  std::vector<PairSelectionView> views = Ring(12);
  views[5].has_pose = false;
  PriorPairOptions options;
  options.prior_neighbors = 2;
  PairSelectionSummary summary;
  Pairs pairs = SelectPriorPairs(views, options, &summary);
  for (const auto& [i, j] : pairs) EXPECT_TRUE(i != 5 && j != 5);
  EXPECT_EQ(summary.num_images_with_pose, 11);
  EXPECT_TRUE(summary.unpaired_images.empty());  // only posed images are counted as unpaired
  options.prior_window = 1;
  pairs = SelectPriorPairs(views, options, &summary);
  EXPECT_TRUE(std::find(pairs.begin(), pairs.end(), std::make_pair(4, 5)) != pairs.end());
  EXPECT_TRUE(std::find(pairs.begin(), pairs.end(), std::make_pair(5, 6)) != pairs.end());
}

TEST(PairSelection, AnIsolatedCameraIsReportedUnpaired) {
  std::vector<PairSelectionView> views = Ring(12);
  // Camera 12 looks away from the object, up at the sky.
  views.push_back(ViewLookingAt({0, 0, 20}, {0, 0, 40}));
  PairSelectionSummary summary;
  SelectPriorPairs(views, PriorPairOptions(), &summary);
  EXPECT_EQ(summary.unpaired_images, std::vector<int>({12}));
}

TEST(PairSelection, NeighboursSurviveAnEightDegreePrior) {
  // Every camera rotated by 8° about a random axis (the ladder's i.i.d. level): the ring
  // neighbours are still chosen.
  const int n = 36;  // 10° apart
  std::vector<PairSelectionView> views = Ring(n);
  std::mt19937 rng(7);
  std::normal_distribution<double> gauss;
  for (auto& view : views) {
    const Eigen::Vector3d axis = DrawVector3([&] { return gauss(rng); }).normalized();
    view.world_from_cam_rotation =
        view.world_from_cam_rotation * Eigen::AngleAxisd(8 * M_PI / 180, axis).toRotationMatrix();
  }
  PriorPairOptions options;
  options.prior_neighbors = 6;
  const Pairs pairs = SelectPriorPairs(views, options, nullptr);
  for (const auto& p : RingPairs(n, 1)) {
    EXPECT_TRUE(std::find(pairs.begin(), pairs.end(), p) != pairs.end())
        << p.first << "-" << p.second;
  }
  for (const auto& [i, j] : pairs) EXPECT_LE(RingDistance(i, j, n), 6) << i << "-" << j;
}

TEST(PairSelection, DeterministicAndSorted) {
  PriorPairOptions options;
  options.prior_neighbors = 5;
  options.prior_window = 2;
  const Pairs a = SelectPriorPairs(Ring(30), options, nullptr);
  const Pairs b = SelectPriorPairs(Ring(30), options, nullptr);
  EXPECT_EQ(a, b);
  EXPECT_TRUE(std::is_sorted(a.begin(), a.end()));
  EXPECT_TRUE(std::adjacent_find(a.begin(), a.end()) == a.end());
  for (const auto& [i, j] : a) EXPECT_LT(i, j);
}

TEST(PairSelection, BadOptionsAreInputErrors) {
  PriorPairOptions options;
  options.prior_neighbors = 0;
  EXPECT_THROW(SelectPriorPairs(Ring(4), options, nullptr), InputError);
  options = PriorPairOptions();
  options.prior_min_overlap = 1.5;
  EXPECT_THROW(SelectPriorPairs(Ring(4), options, nullptr), InputError);
}

}  // namespace
}  // namespace raytime

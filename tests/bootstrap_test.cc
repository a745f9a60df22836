// Prior-free bootstrap (SPEC §4, issue 5) on synthetic scenes with known poses: exact recovery on
// noise-free graphs, robustness to 20 % outlier pairs, the five-point relative pose, the look-at
// seed, the fragility statistic, the graph-support verdict (issue 13), the focal search and the
// prior repairs.
#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <random>

#include "bootstrap/bootstrap.h"
#include "bootstrap/focal_search.h"
#include "bootstrap/look_at_seed.h"
#include "bootstrap/prior_repair.h"
#include "bootstrap/relative_pose.h"
#include "bootstrap/rotation_averaging.h"
#include "bootstrap/translation_averaging.h"
#include "bootstrap/wrong_pairs.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/geometry.h"
#include "testing/random_draws.h"

namespace raytime {
namespace {

Eigen::Vector3d RandomAxis(std::mt19937& rng) {
  std::normal_distribution<double> normal;
  return DrawVector3([&] { return normal(rng); }).normalized();
}

Eigen::Matrix3d RandomRotation(std::mt19937& rng, double max_angle_rad) {
  const Eigen::Vector3d axis = RandomAxis(rng);
  std::uniform_real_distribution<double> uniform(0.0, max_angle_rad);
  return ExpSO3(axis * uniform(rng));
}

// Camera looking from `centre` towards `target` (camera-to-world; y roughly down).
Eigen::Matrix3d LookAtRotation(const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitZ().cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r << x, y, z;
  return r;
}

struct BootstrapScene {
  std::vector<Eigen::Matrix3d> rotations;  // world_from_cam
  std::vector<Eigen::Vector3d> centres;
  std::vector<Eigen::Vector3d> points;
};

// An orbit of cameras around a box of points near the origin (an object capture), camera height
// and aim jittered so no configuration is special.
BootstrapScene OrbitScene(int num_cameras, int num_points, std::mt19937& rng) {
  BootstrapScene scene;
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  for (int i = 0; i < num_cameras; ++i) {
    const double angle = 1.6 * M_PI * i / num_cameras;
    const Eigen::Vector3d centre(6 * std::cos(angle), 6 * std::sin(angle), 1.0 + jitter(rng));
    scene.centres.push_back(centre);
    scene.rotations.push_back(LookAtRotation(centre, DrawVector3([&] { return jitter(rng); })));
  }
  std::uniform_real_distribution<double> box(-1.5, 1.5);
  for (int k = 0; k < num_points; ++k)
    scene.points.push_back(DrawVector3([&] { return box(rng); }));
  return scene;
}

ViewGraphEdge TrueEdge(const BootstrapScene& scene, int i, int j) {
  ViewGraphEdge e;
  e.image1 = i;
  e.image2 = j;
  e.rotation = scene.rotations[j].transpose() * scene.rotations[i];
  e.translation =
      (scene.rotations[j].transpose() * (scene.centres[i] - scene.centres[j])).normalized();
  e.num_correspondences = e.num_inliers = 200 + 10 * ((i * 7 + j * 3) % 13);
  e.median_parallax_deg = 10;
  e.status = PairStatus::kValid;
  return e;
}

std::vector<ViewGraphEdge> AllPairs(const BootstrapScene& scene) {
  std::vector<ViewGraphEdge> edges;
  const int n = static_cast<int>(scene.rotations.size());
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) edges.push_back(TrueEdge(scene, i, j));
  }
  return edges;
}

// Largest angle between the estimated rotations and the truth after the best global rotation.
double MaxRotationErrorDeg(const BootstrapScene& scene,
                           const std::vector<Eigen::Matrix3d>& estimate,
                           const std::vector<bool>& registered) {
  std::vector<Eigen::Matrix3d> offsets;
  for (size_t i = 0; i < estimate.size(); ++i) {
    if (registered[i]) offsets.push_back(scene.rotations[i] * estimate[i].transpose());
  }
  const Eigen::Matrix3d gauge = MedianRotation(offsets);
  double worst = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    if (!registered[i]) continue;
    worst = std::max(worst, DegreesFromRadians(RotationAngle(Eigen::Matrix3d(
                                scene.rotations[i].transpose() * gauge * estimate[i]))));
  }
  return worst;
}

// Largest centre error after the Sim(3) fit, relative to the scene's spread.
double MaxCentreErrorRelative(const BootstrapScene& scene,
                              const std::vector<Eigen::Vector3d>& estimate) {
  const Sim3 fit = FitAlignment(estimate, scene.centres, AlignmentKind::kSim3);
  double worst = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    worst = std::max(worst, (fit * estimate[i] - scene.centres[i]).norm() / 6.0);
  }
  return worst;
}

TEST(ViewGraph, ComponentsAreOrderedBySize) {
  const std::vector<int> labels = ConnectedComponents(6, {{4, 5}, {0, 1}, {1, 2}});
  EXPECT_EQ(labels, (std::vector<int>{0, 0, 0, 2, 1, 1}));
  const std::vector<int> tree = MaximumSpanningForest(3, {{0, 1}, {1, 2}, {0, 2}}, {1.0, 5.0, 3.0});
  EXPECT_EQ(tree, (std::vector<int>{1, 2}));
}

// Two five-node cliques joined by two edges: the cut between any node of one and any of the other
// is the two edges, with the clique as the side.
TEST(ViewGraph, MinimumCutTreeFindsTheWeakLink) {
  std::vector<std::pair<int, int>> edges;
  for (int a = 0; a < 5; ++a) {
    for (int b = a + 1; b < 5; ++b) {
      edges.emplace_back(a, b);
      edges.emplace_back(a + 5, b + 5);
    }
  }
  edges.emplace_back(1, 7);
  edges.emplace_back(3, 8);
  const std::vector<MinimumCut> cuts = MinimumCutTree(10, edges);
  ASSERT_EQ(cuts.size(), 9u);
  int weak = 0;
  for (const MinimumCut& cut : cuts) {
    if (cut.num_edges_across == 2) {
      ++weak;
      const std::vector<int> right{5, 6, 7, 8, 9};
      const std::vector<int> left{0, 1, 2, 3, 4};
      EXPECT_TRUE(cut.side == right || cut.side == left);
    } else {
      // Inside a clique of five: one node against the rest, 4 edges (5 where a link leaves it).
      EXPECT_GE(cut.num_edges_across, 4);
    }
  }
  EXPECT_EQ(weak, 1);
}

// Against brute force on random graphs of 8 nodes: every pair of nodes' minimum cut (the fewest
// edges across any subset holding one and not the other) is the smallest of the tree's cuts
// separating them, and every tree cut's count is the edges its side really has across.
TEST(ViewGraph, MinimumCutTreeHoldsEveryPairsMinimumCut) {
  std::mt19937 rng(7);
  constexpr int kNodes = 8;
  for (int draw = 0; draw < 20; ++draw) {
    std::vector<std::pair<int, int>> edges;
    std::bernoulli_distribution edge(0.45);
    for (int a = 0; a < kNodes; ++a) {
      for (int b = a + 1; b < kNodes; ++b) {
        if (edge(rng)) edges.emplace_back(a, b);
        if (edge(rng) && edge(rng)) edges.emplace_back(a, b);  // a parallel edge, sometimes
      }
    }
    const auto across = [&](unsigned mask) {
      int count = 0;
      for (const auto& [a, b] : edges) count += ((mask >> a) & 1u) != ((mask >> b) & 1u);
      return count;
    };
    const std::vector<MinimumCut> cuts = MinimumCutTree(kNodes, edges);
    ASSERT_EQ(cuts.size(), static_cast<size_t>(kNodes - 1));
    std::vector<unsigned> masks;
    for (const MinimumCut& cut : cuts) {
      unsigned mask = 0;
      for (const int node : cut.side) mask |= 1u << node;
      EXPECT_EQ(across(mask), cut.num_edges_across);
      masks.push_back(mask);
    }
    for (int s = 0; s < kNodes; ++s) {
      for (int t = s + 1; t < kNodes; ++t) {
        int brute = std::numeric_limits<int>::max();
        for (unsigned mask = 0; mask < (1u << kNodes); ++mask) {
          if (((mask >> s) & 1u) && !((mask >> t) & 1u)) brute = std::min(brute, across(mask));
        }
        int tree = std::numeric_limits<int>::max();
        for (size_t k = 0; k < cuts.size(); ++k) {
          if (((masks[k] >> s) & 1u) != ((masks[k] >> t) & 1u)) {
            tree = std::min(tree, cuts[k].num_edges_across);
          }
        }
        EXPECT_EQ(tree, brute) << "draw " << draw << ", nodes " << s << " and " << t;
      }
    }
  }
}

TEST(RotationAveraging, ExactOnNoiseFreeGraph) {
  std::mt19937 rng(1);
  const BootstrapScene scene = OrbitScene(12, 0, rng);
  const std::vector<ViewGraphEdge> edges = AllPairs(scene);
  std::vector<int> all(edges.size());
  for (size_t k = 0; k < all.size(); ++k) all[k] = static_cast<int>(k);
  const RotationAveragingResult result =
      AverageRotations(12, RotationEdges(edges, all), RotationAveragingOptions());
  EXPECT_EQ(result.num_registered, 12);
  EXPECT_TRUE(result.converged);
  EXPECT_LT(MaxRotationErrorDeg(scene, result.world_from_cam, result.registered), 1e-6);
  EXPECT_LT(result.mean_residual_deg, 1e-6);
}

TEST(RotationAveraging, RegistersOnlyTheLargestComponent) {
  std::mt19937 rng(2);
  const BootstrapScene scene = OrbitScene(6, 0, rng);
  const std::vector<ViewGraphEdge> edges = {TrueEdge(scene, 0, 1), TrueEdge(scene, 1, 2),
                                            TrueEdge(scene, 3, 4)};
  const RotationAveragingResult result =
      AverageRotations(6, RotationEdges(edges, {0, 1, 2}), RotationAveragingOptions());
  EXPECT_EQ(result.registered, (std::vector<bool>{true, true, true, false, false, false}));
  EXPECT_TRUE(std::isnan(result.edge_residual_deg[2]));
  RelativeRotation self_loop;
  self_loop.i = self_loop.j = 1;
  EXPECT_THROW(AverageRotations(6, {self_loop}, RotationAveragingOptions()), std::invalid_argument);
}

TEST(TranslationAveraging, ExactOnNoiseFreeGraphUpToSimilarity) {
  std::mt19937 rng(3);
  const BootstrapScene scene = OrbitScene(10, 0, rng);
  std::vector<RelativeDirection> directions;
  for (int i = 0; i < 10; ++i) {
    for (int j = i + 1; j < 10; ++j) {
      if ((i + j) % 3 == 0) continue;  // not complete: LUD must not need every pair
      directions.push_back({i, j, (scene.centres[i] - scene.centres[j]).normalized()});
    }
  }
  const TranslationAveragingResult result =
      AverageTranslations(10, directions, TranslationAveragingOptions());
  EXPECT_EQ(result.num_registered, 10);
  EXPECT_TRUE(result.converged);
  EXPECT_LT(MaxCentreErrorRelative(scene, result.centres), 1e-6);
  EXPECT_LT(result.mean_residual_deg, 1e-5);
  for (double scale : result.edge_scale) EXPECT_GE(scale, 1.0);
}

TEST(TranslationAveraging, RejectsNonUnitDirections) {
  EXPECT_THROW(
      AverageTranslations(2, {{0, 1, Eigen::Vector3d(0, 0, 2)}}, TranslationAveragingOptions()),
      std::invalid_argument);
}

// Global solve (fragility, detector, rotations, LUD) on a graph with 20 % of the pairs replaced
// by gross outliers: random relative rotations and translation directions.
TEST(Bootstrap, RobustToTwentyPercentOutlierPairs) {
  std::mt19937 rng(4);
  const BootstrapScene scene = OrbitScene(16, 0, rng);
  BootstrapResult result;
  result.edges = AllPairs(scene);
  std::vector<bool> outlier(result.edges.size(), false);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> normal;
  int num_outliers = 0;
  for (size_t k = 0; k < result.edges.size(); ++k) {
    ViewGraphEdge& e = result.edges[k];
    // Small noise on every pair, as two-view estimates carry.
    e.rotation = ExpSO3(DrawVector3([&] { return normal(rng); }) * 0.002) * e.rotation;
    if (unit(rng) < 0.2) {
      outlier[k] = true;
      ++num_outliers;
      // The most supported pairs: the spanning-tree initialization is built from outliers.
      e.num_inliers = 1000;
      e.rotation = RandomRotation(rng, M_PI) * e.rotation;
      e.translation = DrawVector3([&] { return normal(rng); }).normalized();
    }
  }
  ASSERT_GT(num_outliers, 15);
  SolveGlobalPoses(16, BootstrapOptions(), &result);
  EXPECT_EQ(result.num_rotations_registered, 16);
  EXPECT_LT(MaxRotationErrorDeg(scene, result.world_from_cam, result.rotation_registered), 0.5);
  EXPECT_LT(MaxCentreErrorRelative(scene, result.centres), 0.02);

  int flagged_outliers = 0, false_positives = 0;
  for (size_t k = 0; k < result.edges.size(); ++k) {
    const bool wrong = result.pairs.scores[k].verdict == PairVerdict::kWrong;
    if (wrong && outlier[k]) ++flagged_outliers;
    if (wrong && !outlier[k]) ++false_positives;
  }
  EXPECT_GE(flagged_outliers, 0.9 * num_outliers);
  EXPECT_LE(false_positives, 0.03 * (result.edges.size() - num_outliers));
  // A corrupted graph is fragile by the paper's statistic; see FragilityIsSmallOnCleanGraph.
  EXPECT_GT(result.fragility.mean_residual_deg, 10.0);
  EXPECT_TRUE(result.fragility.fragile);
}

TEST(Bootstrap, FragilityIsSmallOnCleanGraph) {
  std::mt19937 rng(5);
  const BootstrapScene scene = OrbitScene(12, 0, rng);
  BootstrapResult result;
  result.edges = AllPairs(scene);
  std::normal_distribution<double> normal;
  for (auto& e : result.edges) {
    e.rotation = ExpSO3(DrawVector3([&] { return normal(rng); }) * 0.002) * e.rotation;
  }
  SolveGlobalPoses(12, BootstrapOptions(), &result);
  EXPECT_LT(result.fragility.mean_residual_deg, 0.5);
  EXPECT_FALSE(result.fragility.fragile);
  EXPECT_EQ(result.pairs.num_wrong, 0);
}

TEST(Bootstrap, PureRotationPairsServeRotationsOnly) {
  std::mt19937 rng(6);
  const BootstrapScene scene = OrbitScene(8, 0, rng);
  BootstrapResult result;
  result.edges = AllPairs(scene);
  for (auto& e : result.edges) {
    if (e.image1 == 0) {
      e.status = PairStatus::kPureRotation;
      e.translation = Eigen::Vector3d::UnitX();  // meaningless for a pure rotation
    }
  }
  SolveGlobalPoses(8, BootstrapOptions(), &result);
  EXPECT_LT(MaxRotationErrorDeg(scene, result.world_from_cam, result.rotation_registered), 1e-6);
  // Camera 0 has no translation direction left: it is placed by the look-at fill.
  EXPECT_EQ(result.num_positions_filled, 1);
  EXPECT_EQ(result.num_positions_estimated, 7);
  EXPECT_FALSE(result.position_estimated[0]);
  EXPECT_EQ(result.pairs.num_wrong, 0);
  // One filled centre of eight (12.5 %) and 7 pure rotations of 28 pairs (25 %): still supported.
  EXPECT_EQ(result.support.num_pure_rotation_pairs, 7);
  EXPECT_FALSE(result.support.weak);
  EXPECT_STREQ(FragilityVerdict(result), "not fragile");
}

TEST(GraphSupport, CountsSharesAndReasons) {
  std::vector<ViewGraphEdge> edges(10);
  for (int k = 0; k < 10; ++k) {
    edges[k].status = k < 6 ? PairStatus::kPureRotation
                            : (k < 9 ? PairStatus::kValid : PairStatus::kTooFewInliers);
    edges[k].median_parallax_deg = k;  // usable pairs 0..8: median 4
  }
  GraphSupport support = AssessGraphSupport(edges, {10, 9, 5, 3}, GraphSupportOptions());
  EXPECT_EQ(support.num_usable_pairs, 9);
  EXPECT_EQ(support.num_pure_rotation_pairs, 6);
  EXPECT_EQ(support.num_direction_pairs, 3);
  EXPECT_NEAR(support.pure_rotation_share, 6.0 / 9.0, 1e-12);
  EXPECT_NEAR(support.filled_share, 3.0 / 9.0, 1e-12);
  EXPECT_NEAR(support.median_parallax_deg, 4.0, 1e-12);
  EXPECT_TRUE(support.weak);
  EXPECT_EQ(support.reasons, (std::vector<std::string>{"pure_rotation_share", "filled_share"}));
  EXPECT_NE(DescribeWeakness(support).find("67% of the usable pairs (6 of 9)"), std::string::npos)
      << DescribeWeakness(support);
  EXPECT_EQ(GraphSupportJson(support)["num_positions_filled"], 3);

  GraphSupportOptions lenient;
  lenient.max_pure_rotation_share = 0.7;
  lenient.max_filled_share = 0.4;
  support = AssessGraphSupport(edges, {10, 9, 5, 3}, lenient);
  EXPECT_FALSE(support.weak);
  EXPECT_TRUE(support.reasons.empty());
  EXPECT_EQ(DescribeWeakness(support), "");
  EXPECT_THROW(AssessGraphSupport(edges, {10, 9, 7, 3}, lenient), std::invalid_argument);
  lenient.max_filled_share = 1.5;
  EXPECT_THROW(AssessGraphSupport(edges, {10, 9, 5, 3}, lenient), InputError);
}

Eigen::Vector3d Noisy(const Eigen::Vector3d& ray, double sigma_rad, std::mt19937& rng) {
  std::normal_distribution<double> normal(0.0, sigma_rad);
  return (ray + DrawVector3([&] { return normal(rng); })).normalized();
}

TEST(RelativePose, FivePointRecoversPoseWithOutliers) {
  std::mt19937 rng(7);
  const BootstrapScene scene = OrbitScene(8, 300, rng);
  const int i = 1, j = 3;
  Eigen::Matrix3Xd b1(3, 300), b2(3, 300);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> normal;
  for (int k = 0; k < 300; ++k) {
    b1.col(k) = Noisy(scene.rotations[i].transpose() * (scene.points[k] - scene.centres[i]),
                      0.3 / 1000, rng);
    b2.col(k) = Noisy(scene.rotations[j].transpose() * (scene.points[k] - scene.centres[j]),
                      0.3 / 1000, rng);
    if (k % 4 == 0) {  // 25 % gross outliers
      const Eigen::Vector2d xy = 0.3 * DrawVector2([&] { return normal(rng); });
      b2.col(k) = Eigen::Vector3d(xy.x(), xy.y(), 1).normalized();
    }
  }
  for (const std::string algorithm : {"stewenius", "nister"}) {
    RelativePoseOptions options;
    options.algorithm = algorithm;
    const RelativePoseResult result = EstimateRelativePose(b1, b2, 1000.0, options);
    const ViewGraphEdge truth = TrueEdge(scene, i, j);
    EXPECT_EQ(result.status, PairStatus::kValid) << algorithm;
    EXPECT_LT(DegreesFromRadians(
                  RotationAngle(Eigen::Matrix3d(truth.rotation.transpose() * result.rotation))),
              0.1)
        << algorithm;
    EXPECT_LT(
        DegreesFromRadians(std::acos(std::min(1.0, truth.translation.dot(result.translation)))),
        1.0)
        << algorithm;
    EXPECT_GE(result.inliers.size(), 210u) << algorithm;
    EXPECT_LE(result.inliers.size(), 235u) << algorithm;
  }
}

TEST(RelativePose, FlagsPureRotationAndTooFewInliers) {
  std::mt19937 rng(8);
  const Eigen::Matrix3d rotation = ExpSO3(Eigen::Vector3d(0.05, 0.2, -0.03));
  Eigen::Matrix3Xd b1(3, 200), b2(3, 200);
  std::uniform_real_distribution<double> box(-0.5, 0.5);
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector2d xy = DrawVector2([&] { return box(rng); });
    const Eigen::Vector3d point(xy.x(), xy.y(), 1.0);
    b1.col(k) = Noisy(point.normalized(), 0.2 / 1000, rng);
    b2.col(k) = Noisy(rotation * point.normalized(), 0.2 / 1000, rng);
  }
  const RelativePoseResult result = EstimateRelativePose(b1, b2, 1000.0, RelativePoseOptions());
  EXPECT_EQ(result.status, PairStatus::kPureRotation);
  EXPECT_LT(
      DegreesFromRadians(RotationAngle(Eigen::Matrix3d(rotation.transpose() * result.rotation))),
      0.2);
  const RelativePoseResult few =
      EstimateRelativePose(b1.leftCols(10), b2.leftCols(10), 1000.0, RelativePoseOptions());
  EXPECT_EQ(few.status, PairStatus::kTooFewInliers);
  RelativePoseOptions bad;
  bad.algorithm = "eight_point";
  EXPECT_THROW(EstimateRelativePose(b1, b2, 1000.0, bad), InputError);
}

TEST(LookAtSeed, NeverDegenerate) {
  LookAtSeedOptions options;
  // Every camera with the same orientation: the plain construction would stack all centres.
  const std::vector<Eigen::Matrix3d> same(6, ExpSO3(Eigen::Vector3d(0.1, -0.2, 0.3)));
  const LookAtSeedResult stacked = LookAtSeed(same, options);
  EXPECT_TRUE(stacked.spread_fallback);
  EXPECT_GE(stacked.spread, options.look_at_min_spread * options.look_at_distance - 1e-12);
  for (size_t a = 0; a < same.size(); ++a) {
    for (size_t b = a + 1; b < same.size(); ++b) {
      EXPECT_GT((stacked.centres[a] - stacked.centres[b]).norm(), 1e-3);
    }
  }
  // An orbit: each camera at unit distance behind its optical axis, which passes the origin.
  std::mt19937 rng(9);
  const BootstrapScene scene = OrbitScene(8, 0, rng);
  const LookAtSeedResult orbit = LookAtSeed(scene.rotations, options);
  EXPECT_FALSE(orbit.spread_fallback);
  for (size_t i = 0; i < scene.rotations.size(); ++i) {
    EXPECT_NEAR(orbit.centres[i].norm(), 1.0, 1e-12);
    EXPECT_NEAR((-orbit.centres[i]).normalized().dot(scene.rotations[i].col(2)), 1.0, 1e-12);
  }
}

// Features and matches of a synthetic orbit seen by a pinhole camera with distortion.
struct SyntheticCapture {
  BootstrapScene scene;
  ImageSet images;
  std::vector<ImageFeatures> features;
  std::vector<PairMatches> matches;
};

SyntheticCapture MakeCapture(const BootstrapScene& scene, const CameraIntrinsics& camera,
                             std::mt19937& rng) {
  SyntheticCapture capture;
  capture.scene = scene;
  const int num_cameras = static_cast<int>(scene.rotations.size());
  const int num_points = static_cast<int>(scene.points.size());
  capture.images.cameras = {camera};
  std::normal_distribution<double> noise(0.0, 0.3);
  std::vector<std::vector<int>> row_of_point(num_cameras);
  for (int i = 0; i < num_cameras; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "%04d.jpg", i);
    capture.images.images.push_back({name, camera.width, camera.height, 0});
    std::vector<Eigen::Vector4f> rows;
    row_of_point[i].assign(num_points, -1);
    for (int k = 0; k < num_points; ++k) {
      const Eigen::Vector3d p = capture.scene.rotations[i].transpose() *
                                (capture.scene.points[k] - capture.scene.centres[i]);
      double u[2], ud[2];
      ProjectPinhole(camera.params.data(), p.data(), u);
      DistortPixel(camera.params.data(), u, ud);
      ud[0] += noise(rng);
      ud[1] += noise(rng);
      if (p.z() <= 0 || ud[0] < 0 || ud[1] < 0 || ud[0] > camera.width - 1 ||
          ud[1] > camera.height - 1) {
        continue;
      }
      row_of_point[i][k] = static_cast<int>(rows.size());
      rows.emplace_back(static_cast<float>(ud[0]), static_cast<float>(ud[1]), 2.0f, 0.0f);
    }
    ImageFeatures f;
    f.keypoints.resize(static_cast<Eigen::Index>(rows.size()), 4);
    for (size_t r = 0; r < rows.size(); ++r) f.keypoints.row(r) = rows[r].transpose();
    capture.features.push_back(f);
  }
  for (int i = 0; i < num_cameras; ++i) {
    for (int j = i + 1; j < num_cameras; ++j) {
      std::vector<std::pair<int, int>> m;
      for (int k = 0; k < num_points; ++k) {
        if (row_of_point[i][k] >= 0 && row_of_point[j][k] >= 0) {
          m.emplace_back(row_of_point[i][k], row_of_point[j][k]);
        }
      }
      if (m.size() < 20) continue;
      PairMatches pair;
      pair.image1 = i;
      pair.image2 = j;
      pair.geometry.inlier_matches.resize(static_cast<Eigen::Index>(m.size()), 2);
      for (size_t r = 0; r < m.size(); ++r) {
        pair.geometry.inlier_matches(r, 0) = m[r].first;
        pair.geometry.inlier_matches(r, 1) = m[r].second;
      }
      capture.matches.push_back(pair);
    }
  }
  return capture;
}

SyntheticCapture MakeCapture(int num_cameras, int num_points, const CameraIntrinsics& camera,
                             std::mt19937& rng) {
  const BootstrapScene scene = OrbitScene(num_cameras, num_points, rng);
  return MakeCapture(scene, camera, rng);
}

// A slow hand-held sweep like issue 13's desk capture: the camera turns by `step_deg` per frame
// about a centre that drifts by `baseline` per frame, facing points 3 to 6 units away, so every
// pair is a near-pure rotation (here at most 0.4° of parallax).
BootstrapScene SweepScene(int num_cameras, double step_deg, double baseline, int num_points,
                          std::mt19937& rng) {
  BootstrapScene scene;
  for (int i = 0; i < num_cameras; ++i) {
    const double yaw = RadiansFromDegrees(step_deg * i);
    const Eigen::Vector3d centre(baseline * i, 0.0, 0.0);
    scene.centres.push_back(centre);
    scene.rotations.push_back(
        LookAtRotation(centre, centre + Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0.05)));
  }
  std::uniform_real_distribution<double> azimuth(RadiansFromDegrees(-30.0),
                                                 RadiansFromDegrees(step_deg * num_cameras + 30));
  std::uniform_real_distribution<double> elevation(-0.3, 0.3), distance(3.0, 6.0);
  for (int k = 0; k < num_points; ++k) {
    const double a = azimuth(rng), e = elevation(rng), d = distance(rng);
    scene.points.emplace_back(d * std::cos(e) * std::cos(a), d * std::cos(e) * std::sin(a),
                              d * std::sin(e));
  }
  return scene;
}

CameraIntrinsics TestCamera() {
  CameraIntrinsics camera;
  camera.width = 1200;
  camera.height = 800;
  camera.params = {1000, 1000, 599.5, 399.5, -0.05, 0.01, 0.0005, -0.0003};
  return camera;
}

TEST(Bootstrap, RecoversSyntheticCaptureFromKeypoints) {
  std::mt19937 rng(10);
  const SyntheticCapture capture = MakeCapture(8, 250, TestCamera(), rng);
  for (const std::string positions : {"lud", "look_at"}) {
    BootstrapOptions options;
    options.positions = positions;
    const BootstrapResult result =
        RunBootstrap(capture.images, capture.features, capture.matches, options);
    EXPECT_EQ(result.num_rotations_registered, 8);
    EXPECT_LT(MaxRotationErrorDeg(capture.scene, result.world_from_cam, result.rotation_registered),
              0.1)
        << positions;
    EXPECT_EQ(result.pairs.num_wrong, 0) << positions;
    // A healthy orbit: every pair has parallax, every centre comes from the graph.
    EXPECT_FALSE(result.support.weak) << positions;
    EXPECT_EQ(result.support.num_pure_rotation_pairs, 0) << positions;
    EXPECT_STREQ(FragilityVerdict(result), "not fragile") << positions;
    EXPECT_TRUE(BootstrapWarnings(capture.images, result).empty()) << positions;
    EXPECT_EQ(result.num_positions_filled, 0) << positions;
    if (positions == "lud") {
      EXPECT_EQ(result.num_positions_estimated, 8);
      EXPECT_LT(MaxCentreErrorRelative(capture.scene, result.centres), 0.02);
    } else {
      EXPECT_EQ(result.num_positions_estimated, 0) << "requested look-at seed, not estimated";
    }
    const PoseSet poses = BootstrapPoses(capture.images, result);
    EXPECT_EQ(poses.size(), 8u);
    EXPECT_TRUE(poses.Has("0007.jpg"));
  }
}

// Issue 13: a sweep of near-pure rotations registers every rotation soundly, but no centre comes
// from the graph; the bootstrap says so instead of reporting "not fragile".
TEST(Bootstrap, NearPureRotationSweepIsWeak) {
  std::mt19937 rng(14);
  const SyntheticCapture capture =
      MakeCapture(SweepScene(12, 3.0, 0.002, 600, rng), TestCamera(), rng);
  const BootstrapResult result =
      RunBootstrap(capture.images, capture.features, capture.matches, BootstrapOptions());
  EXPECT_EQ(result.num_rotations_registered, 12);
  EXPECT_LT(MaxRotationErrorDeg(capture.scene, result.world_from_cam, result.rotation_registered),
            0.1);
  EXPECT_FALSE(result.fragility.fragile) << "the rotations agree: the paper's flag cannot see it";
  EXPECT_GT(result.support.num_usable_pairs, 40);
  EXPECT_EQ(result.support.num_pure_rotation_pairs, result.support.num_usable_pairs);
  EXPECT_LT(result.support.median_parallax_deg, 1.0);
  EXPECT_EQ(result.num_positions_estimated, 0);
  EXPECT_EQ(result.num_positions_filled, 12);
  EXPECT_TRUE(result.support.weak);
  EXPECT_EQ(result.support.reasons,
            (std::vector<std::string>{"pure_rotation_share", "filled_share"}));
  EXPECT_STREQ(FragilityVerdict(result), "weak");

  const Warnings warnings = BootstrapWarnings(capture.images, result);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0].code, "weak_bootstrap");
  EXPECT_EQ(warnings[0].images.size(), 12u);
  EXPECT_EQ(warnings[0].details["num_positions_filled"], 12);
  EXPECT_EQ(warnings[0].details["max_pure_rotation_share"], 0.5);
  EXPECT_NE(warnings[0].message.find("near-pure rotations"), std::string::npos);
  const nlohmann::json json = WarningsToJson(warnings);
  EXPECT_EQ(json[0]["code"], "weak_bootstrap");
  EXPECT_EQ(json[0]["images"][0], "0000.jpg");

  // The same sweep walked 0.15 units per frame (about 2° of parallax between neighbours) is
  // estimated from the graph.
  const SyntheticCapture walk = MakeCapture(SweepScene(12, 3.0, 0.15, 600, rng), TestCamera(), rng);
  const BootstrapResult walked =
      RunBootstrap(walk.images, walk.features, walk.matches, BootstrapOptions());
  EXPECT_FALSE(walked.support.weak) << DescribeWeakness(walked.support);
  EXPECT_EQ(walked.num_positions_estimated, 12);
}

TEST(Bootstrap, RejectsInconsistentMatches) {
  std::mt19937 rng(11);
  SyntheticCapture capture = MakeCapture(4, 60, TestCamera(), rng);
  capture.matches[0].geometry.inlier_matches(0, 1) = 100000;
  EXPECT_THROW(RunBootstrap(capture.images, capture.features, capture.matches, BootstrapOptions()),
               InputError);
  BootstrapOptions bad;
  bad.positions = "centroid";
  EXPECT_THROW(ValidateOptions(bad, "bootstrap"), InputError);
  bad = BootstrapOptions();
  bad.focal.focal_max_ratio = bad.focal.focal_min_ratio;  // a relation between two fields
  EXPECT_THROW(ValidateOptions(bad, "bootstrap"), InputError);
}

TEST(FocalSearch, FindsTheFocalOfAnUndistortedCamera) {
  std::mt19937 rng(12);
  CameraIntrinsics camera = TestCamera();
  camera.params = {1000, 1000, 599.5, 399.5, 0, 0, 0, 0};
  const SyntheticCapture capture = MakeCapture(6, 200, camera, rng);
  std::vector<PixelCorrespondences> pairs;
  for (const auto& pair : capture.matches) {
    const auto& m = pair.geometry.inlier_matches;
    PixelCorrespondences pc;
    pc.pixels1.resize(2, m.rows());
    pc.pixels2.resize(2, m.rows());
    for (Eigen::Index k = 0; k < m.rows(); ++k) {
      pc.pixels1.col(k) =
          capture.features[pair.image1].keypoints.row(m(k, 0)).head<2>().transpose().cast<double>();
      pc.pixels2.col(k) =
          capture.features[pair.image2].keypoints.row(m(k, 1)).head<2>().transpose().cast<double>();
    }
    pairs.push_back(pc);
  }
  FocalSearchOptions options;
  options.focal_pairs = 4;
  options.focal_candidates = 16;
  RelativePoseOptions relative;
  relative.max_error_px = 1.0;
  const FocalSearchResult result = SearchFocal(pairs, 1200, 800, options, relative);
  EXPECT_NEAR(result.focal_px, 1000.0, 60.0);
  EXPECT_EQ(result.candidates_px.size(), result.inliers.size());
}

TEST(PriorRepair, RotationsOnlyAndFullReplacement) {
  std::mt19937 rng(13);
  const BootstrapScene scene = OrbitScene(8, 0, rng);
  // Bootstrap poses in their own gauge: a similarity away from the truth.
  Sim3 gauge;
  gauge.scale = 0.3;
  gauge.rotation = Eigen::Quaterniond(ExpSO3(Eigen::Vector3d(0.4, -1.0, 2.0)));
  gauge.translation = Eigen::Vector3d(1, 2, 3);
  PoseSet truth, bootstrap, prior;
  for (int i = 0; i < 8; ++i) {
    const std::string name = std::to_string(i);
    const Rigid3 pose(Eigen::Quaterniond(scene.rotations[i]), scene.centres[i]);
    truth.world_from_cam[name] = pose;
    bootstrap.world_from_cam[name] = gauge.TransformPose(pose);
    // A coarse prior: every rotation 30° off, centres 0.2 off.
    prior.world_from_cam[name] =
        Rigid3(Eigen::Quaterniond(RandomRotation(rng, 0.52) * scene.rotations[i]),
               scene.centres[i] + 0.2 * Eigen::Vector3d::Random());
  }
  prior.world_from_cam["not_in_bootstrap"] = Rigid3();
  PriorRepairSummary summary;
  const PoseSet rotations = RepairRotations(prior, bootstrap, &summary);
  EXPECT_EQ(summary.num_repaired, 8);
  EXPECT_EQ(summary.num_kept_prior, 1);
  // All repaired rotations share one gauge offset from the truth; centres are the prior's.
  std::vector<Eigen::Matrix3d> offsets;
  for (int i = 0; i < 8; ++i) {
    const std::string name = std::to_string(i);
    offsets.push_back(rotations.world_from_cam.at(name).RotationMatrix() *
                      scene.rotations[i].transpose());
    EXPECT_EQ(rotations.world_from_cam.at(name).translation,
              prior.world_from_cam.at(name).translation);
  }
  for (const auto& offset : offsets) {
    EXPECT_LT(DegreesFromRadians(RotationAngle(Eigen::Matrix3d(offset.transpose() * offsets[0]))),
              1e-6);
  }
  const PoseSet replaced = ReplaceWithBootstrap(prior, bootstrap, &summary);
  EXPECT_EQ(summary.num_repaired, 8);
  EXPECT_NEAR(summary.scale, 1.0 / 0.3, 0.3);
  // The replaced poses are the truth up to one similarity (exactly: the bootstrap was exact).
  std::vector<Eigen::Vector3d> centres;
  std::vector<Eigen::Matrix3d> replaced_rotations;
  for (int i = 0; i < 8; ++i) {
    centres.push_back(replaced.world_from_cam.at(std::to_string(i)).translation);
    replaced_rotations.push_back(replaced.world_from_cam.at(std::to_string(i)).RotationMatrix());
  }
  EXPECT_LT(MaxCentreErrorRelative(scene, centres), 1e-9);
  EXPECT_LT(MaxRotationErrorDeg(scene, replaced_rotations, std::vector<bool>(8, true)), 1e-6);

  // The frame of the replacement follows the prior's rotations, not its centres: with centres
  // moved by more than the orbit's size (a 64° prior moves them 80 % of the scene distance), the
  // replaced poses still sit within the prior's rotation noise of the truth's frame.
  PoseSet wild = prior;
  wild.world_from_cam.erase("not_in_bootstrap");
  for (auto& [name, pose] : wild.world_from_cam)
    pose.translation += 3.0 * Eigen::Vector3d::Random();
  const PoseSet wild_replaced = ReplaceWithBootstrap(wild, bootstrap, &summary);
  double mean_error_deg = 0.0;
  for (int i = 0; i < 8; ++i) {
    mean_error_deg += DegreesFromRadians(RotationAngle(Eigen::Matrix3d(
                          wild_replaced.world_from_cam.at(std::to_string(i)).RotationMatrix() *
                          scene.rotations[i].transpose()))) /
                      8.0;
  }
  EXPECT_LT(mean_error_deg, 20.0) << "the prior's rotations are 30° off each";
  EXPECT_GT(summary.scale, 0.0);
}

// repair: auto. A coarse prior (rotations 30° off each) is replaced when the graph supports the
// bootstrap's positions and gets the averaged rotations alone when it does not; an accurate one
// (1° off) is kept unchanged, whatever the graph.
TEST(PriorRepair, AutoRepairsOnlyACoarsePrior) {
  std::mt19937 rng(17);
  const BootstrapScene scene = OrbitScene(8, 0, rng);
  Sim3 gauge;
  gauge.scale = 0.5;
  gauge.rotation = Eigen::Quaterniond(ExpSO3(Eigen::Vector3d(1.0, 0.2, -0.5)));
  const auto rotation_by = [&](double angle_rad) { return ExpSO3(RandomAxis(rng) * angle_rad); };
  PoseSet bootstrap, coarse, accurate;
  for (int i = 0; i < 8; ++i) {
    const std::string name = std::to_string(i);
    const Rigid3 pose(Eigen::Quaterniond(scene.rotations[i]), scene.centres[i]);
    bootstrap.world_from_cam[name] = gauge.TransformPose(pose);
    const Eigen::Vector3d centre = scene.centres[i] + 0.1 * Eigen::Vector3d::Random();
    coarse.world_from_cam[name] =
        Rigid3(Eigen::Quaterniond(rotation_by(0.52) * scene.rotations[i]), centre);
    accurate.world_from_cam[name] =
        Rigid3(Eigen::Quaterniond(rotation_by(0.0175) * scene.rotations[i]), centre);
  }
  PriorRepairSummary summary;
  const PoseSet replaced = RepairIfCoarse(coarse, bootstrap, 20.0, true, &summary);
  EXPECT_EQ(summary.mode, "replace");
  EXPECT_EQ(summary.num_repaired, 8);
  EXPECT_GT(summary.median_rotation_change_deg, 20.0);
  EXPECT_EQ(summary.min_rotation_change_deg, 20.0);
  const PoseSet expected_replaced = ReplaceWithBootstrap(coarse, bootstrap);
  const PoseSet rotations = RepairIfCoarse(coarse, bootstrap, 20.0, false, &summary);
  EXPECT_EQ(summary.mode, "rotations");
  const PoseSet expected_rotations = RepairRotations(coarse, bootstrap);
  for (int i = 0; i < 8; ++i) {
    const std::string name = std::to_string(i);
    EXPECT_TRUE(replaced.world_from_cam.at(name).translation.isApprox(
        expected_replaced.world_from_cam.at(name).translation));
    EXPECT_TRUE(rotations.world_from_cam.at(name).rotation.isApprox(
        expected_rotations.world_from_cam.at(name).rotation));
    EXPECT_EQ(rotations.world_from_cam.at(name).translation,
              coarse.world_from_cam.at(name).translation);
  }
  for (const bool supported : {true, false}) {
    const PoseSet kept = RepairIfCoarse(accurate, bootstrap, 20.0, supported, &summary);
    EXPECT_EQ(summary.mode, "none");
    EXPECT_EQ(summary.num_repaired, 0);
    EXPECT_EQ(summary.num_kept_prior, 8);
    EXPECT_LT(summary.median_rotation_change_deg, 2.0);
    for (const auto& [name, pose] : accurate.world_from_cam) {
      EXPECT_EQ(kept.world_from_cam.at(name).rotation.coeffs(), pose.rotation.coeffs());
      EXPECT_EQ(kept.world_from_cam.at(name).translation, pose.translation);
    }
  }
}

}  // namespace
}  // namespace raytime

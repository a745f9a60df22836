// The matches stage with `pairs: prior` (issue 10, "Prior-guided pairs"): it needs the prior's pose
// set from an earlier stage and says so clearly when the pipeline puts it first; given the poses,
// it matches only the chosen pairs and summarizes the choice against the exhaustive count. The
// inputs are a synthetic ring of cameras around a point cloud whose points carry one descriptor
// each, written in raytime's HDF5 schema.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
#include <set>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "pipelines/stage.h"
#include "temp_dir.h"
#include "testing/random_draws.h"
#include "tests/input_error_of.h"
#include "tests/run_stage.h"

namespace raytime {
namespace {

struct RingScene {
  ImageSet images;
  std::vector<ImageFeatures> features;
  PoseSet poses;
};

// `n` cameras on a circle of radius 5 looking at a cloud of 400 points within 1.5 of its centre;
// a point's keypoint in every image that sees it has the point's descriptor plus a little noise.
RingScene MakeRingScene(int n) {
  RingScene scene;
  CameraIntrinsics camera;
  camera.width = 640;
  camera.height = 480;
  camera.params = {500, 500, 319.5, 239.5, 0, 0, 0, 0};
  scene.images.cameras = {camera};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uniform(-1.5, 1.5);
  std::uniform_int_distribution<int> byte(0, 60);
  std::normal_distribution<double> noise(0.0, 1.0);
  const int num_points = 400;
  std::vector<Eigen::Vector3d> points(num_points);
  std::vector<std::vector<int>> descriptors(num_points, std::vector<int>(128));
  for (int p = 0; p < num_points; ++p) {
    points[p] = DrawVector3([&] { return uniform(rng); });
    for (int& value : descriptors[p]) value = byte(rng);
  }
  for (int i = 0; i < n; ++i) {
    char name[16];
    std::snprintf(name, sizeof(name), "%04d.jpg", i);
    scene.images.images.push_back({name, camera.width, camera.height, 0});
    const double a = 2 * M_PI * i / n;
    const Eigen::Vector3d centre = 5 * Eigen::Vector3d(std::cos(a), std::sin(a), 0);
    const Eigen::Vector3d z = -centre.normalized();
    const Eigen::Vector3d x = z.cross(Eigen::Vector3d(0, 0, -1)).normalized();
    Eigen::Matrix3d world_from_cam;
    world_from_cam << x, z.cross(x), z;
    scene.poses.world_from_cam[name] = Rigid3(Eigen::Quaterniond(world_from_cam), centre);
    std::vector<Eigen::Vector4f> keypoints;
    std::vector<std::vector<int>> rows;
    for (int p = 0; p < num_points; ++p) {
      const Eigen::Vector3d in_cam = world_from_cam.transpose() * (points[p] - centre);
      const double u = 500 * in_cam.x() / in_cam.z() + 319.5;
      const double v = 500 * in_cam.y() / in_cam.z() + 239.5;
      const double dv = 0.3 * noise(rng);
      keypoints.emplace_back(u + 0.3 * noise(rng), v + dv, 2.0f, 0.0f);
      std::vector<int> row = descriptors[p];
      for (int& value : row) value = std::clamp(value + static_cast<int>(noise(rng)), 0, 255);
      rows.push_back(row);
    }
    ImageFeatures features;
    features.keypoints.resize(num_points, 4);
    features.descriptors.resize(num_points, 128);
    for (int p = 0; p < num_points; ++p) {
      features.keypoints.row(p) = keypoints[p].transpose();
      for (int c = 0; c < 128; ++c) features.descriptors(p, c) = static_cast<uint8_t>(rows[p][c]);
    }
    scene.features.push_back(features);
  }
  return scene;
}

// Writes the scene's HDF5 inputs (the pose set "prior" only when `with_prior`) and runs a matches
// stage configured by `options`.
nlohmann::json RunMatches(const RingScene& scene, const TempDir& dir, const std::string& options,
                          bool with_prior, std::vector<PairMatches>* pairs = nullptr) {
  {
    Hdf5Writer writer(dir / "inputs.h5");
    writer.WriteImages(scene.images);
    writer.WriteFeatures(scene.features, Provenance{"test", {}, "", ""});
    if (with_prior) {
      writer.WritePoseSet("prior", scene.poses, PoseRole::kPrior, Provenance{"test", {}, "", ""});
    }
    writer.Commit();
  }
  std::map<std::string, std::string> artifacts = {{"images", dir / "inputs.h5"},
                                                  {"features", dir / "inputs.h5"}};
  if (with_prior) artifacts["poses/prior"] = dir / "inputs.h5";
  const nlohmann::json summary =
      RunStageInProcess("matches", options, dir.path().string(), artifacts);
  if (pairs) *pairs = Hdf5Reader(dir / "matches.h5").ReadMatches();
  return summary;
}

TEST(MatchesStage, PriorPairsBeforeThePriorStageIsAClearError) {
  TempDir dir("matches_stage");
  const RingScene scene = MakeRingScene(6);
  {
    const std::string message =
        InputErrorOf([&] { RunMatches(scene, dir, "{pairs: prior}", /*with_prior=*/false); });
    EXPECT_NE(message.find("pairs 'prior'"), std::string::npos) << message;
    EXPECT_NE(message.find("pose set 'prior'"), std::string::npos) << message;
    EXPECT_NE(message.find("put the prior stage before matches"), std::string::npos) << message;
  }
  // The pose set is a declared input only with pairs: prior (so the stage cache keys on it).
  std::unique_ptr<Stage> stage = CreateStage("matches");
  stage->Configure(YAML::Load("{pairs: prior, prior_poses: prior@arkit}"), "test");
  EXPECT_EQ(stage->Inputs(), std::vector<std::string>({"images", "features", "poses/prior@arkit"}));
  stage->Configure(YAML::Load("{}"), "test");
  EXPECT_EQ(stage->Inputs(), std::vector<std::string>({"images", "features"}));
}

TEST(MatchesStage, PriorPairsMatchOnlyTheChosenPairsAndSummarizeTheChoice) {
  TempDir dir("matches_stage");
  const int n = 12;
  const RingScene scene = MakeRingScene(n);
  std::vector<PairMatches> pairs;
  const nlohmann::json summary =
      RunMatches(scene, dir, "{pairs: prior, prior_neighbors: 2}", /*with_prior=*/true, &pairs);
  const nlohmann::json& selection = summary.at("pair_selection");
  EXPECT_EQ(selection.at("num_exhaustive_pairs"), n * (n - 1) / 2);
  EXPECT_EQ(selection.at("num_pairs"), n);  // each camera with its two ring neighbours
  EXPECT_EQ(summary.at("num_pairs"), n);
  EXPECT_EQ(selection.at("pose_set"), "prior");
  EXPECT_TRUE(summary.at("warnings").empty());
  // Every verified pair is a pair of ring neighbours, and every one of them verifies.
  EXPECT_EQ(pairs.size(), size_t(n));
  for (const PairMatches& pair : pairs) {
    const int d = std::abs(pair.image1 - pair.image2);
    EXPECT_TRUE(d == 1 || d == n - 1) << pair.image1 << "-" << pair.image2;
    EXPECT_GT(pair.geometry.inlier_matches.rows(), 100);
  }
  // Exhaustive matching of the same inputs matches every pair and needs no pose.
  const nlohmann::json exhaustive = RunMatches(scene, dir, "{}", /*with_prior=*/false);
  EXPECT_EQ(exhaustive.at("num_pairs"), n * (n - 1) / 2);
  EXPECT_FALSE(exhaustive.contains("pair_selection"));
}

TEST(MatchesStage, AnImageWithoutPartnerIsAWarning) {
  TempDir dir("matches_stage");
  RingScene scene = MakeRingScene(6);
  // Image 0005 looks straight down, 90° from every other camera's optical axis.
  Rigid3& pose = scene.poses.world_from_cam.at("0005.jpg");
  pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  const nlohmann::json summary = RunMatches(scene, dir, "{pairs: prior}", /*with_prior=*/true);
  ASSERT_EQ(summary.at("warnings").size(), 1u) << summary.dump();
  const nlohmann::json& warning = summary.at("warnings")[0];
  EXPECT_EQ(warning.at("code"), "unpaired_images");
  EXPECT_EQ(warning.at("images"), nlohmann::json::array({"0005.jpg"}));
  EXPECT_EQ(summary.at("pair_selection").at("unpaired_images"),
            nlohmann::json::array({"0005.jpg"}));
}

}  // namespace
}  // namespace raytime

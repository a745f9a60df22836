// COLMAP database interop and the classical control against the real COLMAP 3.8 binary, on five
// images of the sample scene (fountain-P11 at 768x512): a database made by COLMAP's own
// feature_extractor + exhaustive_matcher imports with the counts SQL reports and epipolar
// geometry that holds in raytime's pixel convention; a database we export has COLMAP's exact
// schema and feeds point_triangulator and mapper; the control from ground truth stays at ground
// truth; the pipeline stages run end to end through the raytime binary.
//
// The COLMAP database is built once (about 15 s) into the build tree and reused by every test
// process (ctest runs each test in its own process).
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/atomic_file.h"
#include "core/statistics.h"
#include "evaluate/classical_control.h"
#include "evaluate/pose_errors.h"
#include "formats/colmap_database.h"
#include "formats/colmap_model.h"
#include "formats/strecha.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// Every other view of the arc: four consecutive views are so close to collinear that a Sim(3)
// fit of centres leaves the rotation about their line loose (0.57° for 0003-0006 by hand).
const char* const kSceneImages[] = {"0001.jpg", "0003.jpg", "0005.jpg", "0007.jpg", "0009.jpg"};

std::string Quoted(const std::string& s) {
  std::string quoted = "'";
  for (const char c : s) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// Runs a shell command; returns its exit status and combined output.
int Shell(const std::string& command, std::string* output) {
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  char buffer[4096];
  output->clear();
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) output->append(buffer, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Five sample images in the Strecha layout and a COLMAP-made database of them, cached in the
// build tree. COLMAP gets the ground-truth intrinsics as PINHOLE with the principal point moved
// by +0.5 into its pixel convention, as the shared scenes' reference numbers were made.
struct Fixture {
  std::string scene;     // Strecha layout: images/, gt_dense_cameras/
  std::string database;  // made by COLMAP
  ImageSet images;       // image_root = scene/images
  PoseSet ground_truth;
};

const Fixture& GetFixture() {
  static const Fixture fixture = [] {
    Fixture f;
    const fs::path root = fs::path(RAYTIME_TEST_SCRATCH_DIR) / "v2";
    const fs::path sample = fs::path(RAYTIME_SOURCE_DIR) / "data/sample/fountain-P11";
    f.scene = (root / "scene").string();
    f.database = (root / "colmap" / "database.db").string();
    if (!fs::exists(f.database)) {
      const fs::path tmp = root / ("tmp." + std::to_string(getpid()));
      fs::remove_all(tmp);
      fs::create_directories(tmp / "scene/images");
      fs::create_directories(tmp / "scene/gt_dense_cameras");
      for (const char* name : kSceneImages) {
        fs::copy_file(sample / "images" / name, tmp / "scene/images" / name);
        fs::copy_file(sample / "gt_dense_cameras" / (std::string(name) + ".camera"),
                      tmp / "scene/gt_dense_cameras" / (std::string(name) + ".camera"));
      }
      const CameraIntrinsics k = ReadStrechaCamera((tmp / "scene/gt_dense_cameras" /
                                                    (std::string(kSceneImages[0]) + ".camera"))
                                                       .string())
                                     .intrinsics;
      std::ostringstream params;
      params.precision(17);
      params << k.fx() << "," << k.fy() << "," << k.cx() + 0.5 << "," << k.cy() + 0.5;
      const std::string db = (tmp / "database.db").string();
      const std::string env = "QT_QPA_PLATFORM=offscreen colmap ";
      std::string output;
      const std::string extract =
          env + "feature_extractor --database_path " + Quoted(db) + " --image_path " +
          Quoted((tmp / "scene/images").string()) +
          " --ImageReader.camera_model PINHOLE --ImageReader.single_camera 1"
          " --ImageReader.camera_params " +
          params.str() +
          " --SiftExtraction.use_gpu 0 --SiftExtraction.max_num_features 1024"
          " --SiftExtraction.num_threads 2";
      if (Shell(extract, &output) != 0) {
        throw std::runtime_error("COLMAP feature_extractor failed: " + extract + "\n" + output);
      }
      const std::string match = env + "exhaustive_matcher --database_path " + Quoted(db) +
                                " --SiftMatching.use_gpu 0 --SiftMatching.num_threads 2";
      if (Shell(match, &output) != 0) {
        throw std::runtime_error("COLMAP exhaustive_matcher failed: " + match + "\n" + output);
      }
      // Publish scene and database together; a concurrent builder's copy is as good as ours.
      fs::create_directories(tmp / "colmap");
      fs::rename(db, tmp / "colmap/database.db");
      std::error_code exists;
      fs::rename(tmp / "scene", f.scene, exists);
      fs::rename(tmp / "colmap", root / "colmap", exists);
      fs::remove_all(tmp);
    }
    ReadStrechaScene(f.scene, &f.images, &f.ground_truth);
    return f;
  }();
  return fixture;
}

// Rows of a query as strings.
std::vector<std::vector<std::string>> Query(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
  std::vector<std::vector<std::string>> rows;
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    std::vector<std::string> row;
    for (int c = 0; c < sqlite3_column_count(stmt); ++c) {
      const auto* text = sqlite3_column_text(stmt, c);
      row.push_back(text ? reinterpret_cast<const char*>(text) : "NULL");
    }
    rows.push_back(row);
  }
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return rows;
}

// Sampson distance (px) of a correspondence under F.
double Sampson(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector3d x1(a.x(), a.y(), 1), x2(b.x(), b.y(), 1);
  const Eigen::Vector3d fx1 = F * x1, ftx2 = F.transpose() * x2;
  const double e = x2.dot(fx1);
  return std::abs(e) / std::sqrt(fx1.head<2>().squaredNorm() + ftx2.head<2>().squaredNorm());
}

// Runs a COLMAP command, failing the test with its output.
void Colmap(const std::string& args) {
  std::string output;
  const std::string command = "QT_QPA_PLATFORM=offscreen colmap " + args;
  ASSERT_EQ(Shell(command, &output), 0) << command << "\n" << output;
}

TEST(ColmapDatabaseReal, ImportAgreesWithSqlAndEpipolarGeometry) {
  const Fixture& f = GetFixture();
  const ColmapDatabase db = ReadColmapDatabase(f.database);
  ASSERT_EQ(db.images.images.size(), 5u);
  ASSERT_EQ(db.images.cameras.size(), 1u);
  for (int p = 0; p < kNumIntrinsics; ++p) {
    EXPECT_NEAR(db.images.cameras[0].params[p], f.images.cameras[0].params[p], 1e-9) << p;
  }

  // Keypoints per image, by name.
  std::map<std::string, int> keypoints_sql;
  for (const auto& row : Query(f.database,
                               "SELECT name, rows, cols FROM images JOIN keypoints USING "
                               "(image_id)")) {
    keypoints_sql[row[0]] = std::stoi(row[1]);
    EXPECT_EQ(row[2], "6");  // COLMAP 3.8 writes the affine shape
  }
  for (size_t i = 0; i < db.images.images.size(); ++i) {
    EXPECT_EQ(db.features[i].keypoints.rows(), keypoints_sql.at(db.images.images[i].name));
    EXPECT_EQ(db.features[i].descriptors.rows(), db.features[i].keypoints.rows());
    EXPECT_EQ(db.features[i].descriptors.cols(), 128);
    EXPECT_GT(db.features[i].keypoints.col(2).minCoeff(), 0.0f);
  }

  // Matches and inliers per pair, joined by names, from SQL's own pair-id arithmetic.
  const std::string pair_sql =
      "SELECT a.name, b.name, m.rows, g.rows, g.config FROM matches m"
      " JOIN two_view_geometries g USING (pair_id)"
      " JOIN images a ON a.image_id = m.pair_id / 2147483647"
      " JOIN images b ON b.image_id = m.pair_id % 2147483647";
  std::map<std::pair<std::string, std::string>, std::vector<int>> pairs_sql;
  for (const auto& row : Query(f.database, pair_sql)) {
    pairs_sql[{std::min(row[0], row[1]), std::max(row[0], row[1])}] = {
        std::stoi(row[2]), std::stoi(row[3]), std::stoi(row[4])};
  }
  ASSERT_EQ(db.pairs.size(), pairs_sql.size());
  ASSERT_EQ(db.pairs.size(), 10u);
  long total_matches = 0, total_inliers = 0;
  std::vector<double> all_errors;
  for (const PairMatches& pair : db.pairs) {
    const std::string& n1 = db.images.images[pair.image1].name;
    const std::string& n2 = db.images.images[pair.image2].name;
    const std::vector<int>& sql = pairs_sql.at({n1, n2});
    EXPECT_EQ(pair.matches.rows(), sql[0]) << n1 << " " << n2;
    EXPECT_EQ(pair.geometry.inlier_matches.rows(), sql[1]) << n1 << " " << n2;
    EXPECT_EQ(static_cast<int>(pair.geometry.config), sql[2]) << n1 << " " << n2;
    total_matches += pair.matches.rows();
    total_inliers += pair.geometry.inlier_matches.rows();
    if (pair.geometry.inlier_matches.rows() == 0) continue;
    // COLMAP's F, read row-major and moved into OpenCV pixels, holds for the imported inliers.
    std::vector<double> errors;
    for (Eigen::Index r = 0; r < pair.geometry.inlier_matches.rows(); ++r) {
      const auto k1 = db.features[pair.image1].keypoints.row(pair.geometry.inlier_matches(r, 0));
      const auto k2 = db.features[pair.image2].keypoints.row(pair.geometry.inlier_matches(r, 1));
      errors.push_back(
          Sampson(pair.geometry.F, Eigen::Vector2d(k1(0), k1(1)), Eigen::Vector2d(k2(0), k2(1))));
    }
    // Per pair below half COLMAP's 4 px inlier threshold: its RANSAC is seeded per thread from
    // the clock, and one run in CI left 0005-0009 with a poorer F (upper median 1.04 px, usually
    // 0.15-0.19 px). A wrong reading (transposed, column-major) is off by tens of pixels.
    EXPECT_LT(UpperMedian(errors, 0.0), 2.0) << n1 << " " << n2;
    all_errors.insert(all_errors.end(), errors.begin(), errors.end());
  }
  // Over every pair's inliers the fit is sub-pixel (per pair 0.10-0.52 px in six runs).
  EXPECT_LT(UpperMedian(all_errors, 0.0), 0.5);
  const auto totals = Query(f.database,
                            "SELECT (SELECT sum(rows) FROM matches), (SELECT sum(rows) FROM "
                            "two_view_geometries)");
  EXPECT_EQ(total_matches, std::stol(totals[0][0]));
  EXPECT_EQ(total_inliers, std::stol(totals[0][1]));
  EXPECT_GT(total_inliers, 300);
}

TEST(ColmapDatabaseReal, ExportHasColmapsSchema) {
  const Fixture& f = GetFixture();
  TempDir dir("colmapctl");
  const ColmapDatabase db = ReadColmapDatabase(f.database);
  WriteColmapDatabase(dir / "database.db", db.images, db.features, db.pairs);
  const std::string schema_sql = "SELECT type, name, sql FROM sqlite_master ORDER BY name";
  EXPECT_EQ(Query(dir / "database.db", schema_sql), Query(f.database, schema_sql));
  EXPECT_EQ(Query(dir / "database.db", "PRAGMA user_version"),
            Query(f.database, "PRAGMA user_version"));
  // Our ids are name order (as ToColmapModel's). COLMAP's are extraction order, which its
  // multi-threaded feature_extractor does not keep in name order (it gave 0003.jpg id 1 here).
  EXPECT_EQ(Query(dir / "database.db", "SELECT image_id, name, camera_id FROM images"),
            (std::vector<std::vector<std::string>>{{"1", "0001.jpg", "1"},
                                                   {"2", "0003.jpg", "1"},
                                                   {"3", "0005.jpg", "1"},
                                                   {"4", "0007.jpg", "1"},
                                                   {"5", "0009.jpg", "1"}}));
  const std::string by_name = "SELECT name FROM images ORDER BY name";
  EXPECT_EQ(Query(dir / "database.db", by_name), Query(f.database, by_name));
}

// point_triangulator accepts the exported database, triangulates as much as from COLMAP's own,
// and keeps the poses it is given (only bundle_adjuster moves them).
TEST(ColmapDatabaseReal, PointTriangulatorRunsOnExport) {
  const Fixture& f = GetFixture();
  TempDir dir("colmapctl");
  const ColmapDatabase db = ReadColmapDatabase(f.database);
  WriteColmapDatabase(dir / "database.db", db.images, db.features, db.pairs);
  // point_triangulator needs the model's image ids to be the database's: name order for ours
  // (ToColmapModel), extraction order for COLMAP's.
  const ColmapModel prior = ToColmapModel(f.images, f.ground_truth);
  ColmapModel prior_colmap_ids = prior;
  prior_colmap_ids.images.clear();
  for (const auto& row : Query(f.database, "SELECT image_id, name FROM images")) {
    ColmapImage image = prior.images.at(f.images.Find(row[1]) + 1);
    image.image_id = static_cast<uint32_t>(std::stoul(row[0]));
    prior_colmap_ids.images[image.image_id] = image;
  }
  WriteColmapModelText(prior, dir / "prior0");
  WriteColmapModelText(prior_colmap_ids, dir / "prior1");
  size_t num_points[2] = {0, 0};
  const std::string databases[2] = {dir / "database.db", f.database};
  for (int d = 0; d < 2; ++d) {
    const std::string out = dir / ("triangulated" + std::to_string(d));
    const std::string input = dir / ("prior" + std::to_string(d));
    fs::create_directories(out);
    Colmap("point_triangulator --database_path " + Quoted(databases[d]) + " --image_path " +
           Quoted(f.images.image_root) + " --input_path " + Quoted(input) + " --output_path " +
           Quoted(out));
    if (HasFatalFailure()) return;
    const ColmapModel model = ReadColmapModel(out);
    const ColmapModel given_model = ReadColmapModelText(input);
    num_points[d] = model.points3D.size();
    ASSERT_EQ(model.images.size(), 5u);
    for (const auto& [id, image] : model.images) {
      const Rigid3& given = given_model.images.at(id).cam_from_world;
      EXPECT_LT(image.cam_from_world.rotation.angularDistance(given.rotation), 1e-12);
      EXPECT_LT((image.cam_from_world.translation - given.translation).norm(), 1e-12);
      EXPECT_EQ(image.points2D.size(),
                size_t(db.features[f.images.Find(image.name)].keypoints.rows()));
    }
  }
  EXPECT_GT(num_points[0], 200u);
  // Keypoints come back shifted by exactly 0.5 (up to float32 rounding): the same structure.
  EXPECT_NEAR(double(num_points[0]), double(num_points[1]), 0.01 * num_points[1]);
}

TEST(ClassicalControl, FromGroundTruthStaysAtGroundTruth) {
  const Fixture& f = GetFixture();
  TempDir dir("colmapctl");
  const ColmapDatabase db = ReadColmapDatabase(f.database);
  WriteColmapDatabase(dir / "database.db", db.images, db.features, db.pairs);
  ClassicalControlSummary summary;
  const PoseSet poses = RunClassicalControl(dir / "database.db", f.images, f.ground_truth,
                                            ClassicalControlOptions(), dir / "work", &summary);
  ASSERT_EQ(poses.size(), 5u);
  const PoseErrorSummary errors = ComputePoseErrors(poses, f.ground_truth, PoseErrorOptions());
  EXPECT_LT(errors.mean_rotation_deg, 0.5);
  EXPECT_EQ(summary.mode, "triangulate");
  EXPECT_EQ(summary.rounds, 2);
  ASSERT_EQ(summary.per_round.size(), 2u);
  EXPECT_EQ(summary.num_registered, 5);
  EXPECT_GT(summary.num_points, 200);
  EXPECT_EQ(summary.num_points, summary.per_round.back().num_points);
  EXPECT_GT(summary.num_observations, 2 * summary.num_points);
  EXPECT_LT(summary.mean_reprojection_error_px, 1.5);
  // COLMAP's RMS-like "Final cost" and our mean of the same residuals are the same order.
  EXPECT_GT(summary.colmap_final_cost_px, 0.1 * summary.mean_reprojection_error_px);
  EXPECT_LT(summary.colmap_final_cost_px, 10 * summary.mean_reprojection_error_px);
  EXPECT_GT(summary.wall_time_s, 0.0);
  const std::string log = ReadTextFile(summary.log_path);
  EXPECT_NE(log.find("point_triangulator"), std::string::npos);
  EXPECT_NE(log.find("--BundleAdjustment.refine_focal_length 0"), std::string::npos);
  EXPECT_TRUE(fs::exists(dir / "work/prior/points3D.txt"));
  EXPECT_TRUE(fs::exists(dir / "work/round_2/adjusted"));
  std::cout << "control from ground truth: " << errors.mean_rotation_deg << " deg mean, "
            << summary.ToJson().dump() << "\n";
}

TEST(ClassicalControl, MapperRunsOnExportedDatabase) {
  const Fixture& f = GetFixture();
  TempDir dir("colmapctl");
  const ColmapDatabase db = ReadColmapDatabase(f.database);
  WriteColmapDatabase(dir / "database.db", db.images, db.features, db.pairs);
  ClassicalControlOptions options;
  options.mode = "mapper";
  ClassicalControlSummary summary;
  const PoseSet poses = RunClassicalControl(dir / "database.db", f.images, PoseSet(), options,
                                            dir / "work", &summary);
  EXPECT_GE(poses.size(), 4u);
  const PoseErrorSummary errors = ComputePoseErrors(poses, f.ground_truth, PoseErrorOptions());
  EXPECT_LT(errors.mean_rotation_deg, 1.0);
  EXPECT_EQ(summary.rounds, 1);
  EXPECT_GT(summary.num_points, 100);
}

TEST(ClassicalControl, FailingColmapNamesCommandAndLog) {
  const Fixture& f = GetFixture();
  TempDir dir("colmapctl");
  ClassicalControlOptions options;
  options.colmap = "false";  // exits 1 like a failing COLMAP command
  try {
    RunClassicalControl(f.database, f.images, f.ground_truth, options, dir / "work", nullptr);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("false point_triangulator --database_path"), std::string::npos)
        << message;
    EXPECT_NE(message.find(dir / "work/colmap.log"), std::string::npos) << message;
  }
  options.colmap = "/nonexistent/colmap";
  try {
    RunClassicalControl(f.database, f.images, f.ground_truth, options, dir / "work", nullptr);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot run"), std::string::npos) << e.what();
  }
}

// The stages end to end: colmap_import -> prior (ground truth) -> classical -> evaluate.
TEST(ClassicalControl, PipelineStagesRunThroughTheBinary) {
  const Fixture& f = GetFixture();
  TempDir dir("colmapctl");
  const auto write_pipeline = [&](const std::string& name, const std::string& root) {
    std::ofstream(dir / name) << "name: classical_test\n"
                              << "dataset: {format: strecha, root: " << root << "}\n"
                              << "workdir: " << dir / "work"
                              << "\n"
                              << "stages:\n"
                              << "  - colmap_import: {path: " << f.database << "}\n"
                              << "  - prior: {source: ground_truth}\n"
                              << "  - classical: {rounds: 2}\n"
                              << "  - evaluate: {poses: [classical], alignments: [sim3]}\n";
    return dir / name;
  };
  std::string output;
  const std::string run = std::string(RAYTIME_BINARY) + " run ";
  ASSERT_EQ(Shell(run + Quoted(write_pipeline("ok.yaml", f.scene)), &output), 0) << output;
  const auto summary = nlohmann::json::parse(ReadTextFile(dir / "work/summary.json"));
  const double mean = summary["metrics"]["classical"]["sim3"]["mean_rotation_deg"];
  EXPECT_LT(mean, 0.5);
  EXPECT_TRUE(fs::exists(dir / "work/classical/database.db"));
  EXPECT_TRUE(fs::exists(dir / "work/classical/colmap.log"));

  // The whole sample scene has 6 images the database does not: reported by name, exit code 2.
  const std::string sample = std::string(RAYTIME_SOURCE_DIR) + "/data/sample/fountain-P11";
  EXPECT_EQ(Shell(run + Quoted(write_pipeline("mismatch.yaml", sample)), &output), 2) << output;
  EXPECT_NE(output.find("image names do not match the dataset: 6 name(s) only in dataset: "
                        "0000.jpg, 0002.jpg, 0004.jpg"),
            std::string::npos)
      << output;
}

}  // namespace
}  // namespace raytime

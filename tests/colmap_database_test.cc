// COLMAP database interop without the COLMAP binary: raytime types -> database.db -> raytime
// types, the pixel-convention shift of keypoints, F and H, COLMAP's other keypoint layouts,
// pairs whose COLMAP ids run against name order, and the errors on foreign or corrupt files.
// (tests/colmap_control_test.cc checks the same code against COLMAP 3.8 itself.)
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <stdlib.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>

#include "core/error.h"
#include "formats/colmap_database.h"
#include "testing/random_draws.h"
#include "tests/input_error_of.h"
#include "tests/temp_dir.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// Runs SQL on a database file (to corrupt it or to read raw values).
void Sql(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
  const std::string message = error ? error : "";
  sqlite3_free(error);
  sqlite3_close(db);
  ASSERT_EQ(rc, SQLITE_OK) << message;
}

// First column of the first row of a query as a blob.
std::string SqlBlob(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK);
  std::string blob;
  if (sqlite3_step(stmt) == SQLITE_ROW) {
    blob.assign(static_cast<const char*>(sqlite3_column_blob(stmt, 0)),
                sqlite3_column_bytes(stmt, 0));
  }
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return blob;
}

Eigen::Matrix3d RandomMatrix(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::Matrix3d m;
  for (int i = 0; i < 9; ++i) m.data()[i] = u(rng);
  return m;
}

// Four images over two cameras (one with distortion), keypoints on a 1/256 px grid (so the 0.5
// px shift is exact in float32), random descriptors, five pairs including an empty one.
struct DatabaseScene {
  ImageSet images;
  std::vector<ImageFeatures> features;
  std::vector<PairMatches> pairs;
};

DatabaseScene MakeDatabaseScene() {
  std::mt19937 rng(7);
  DatabaseScene s;
  CameraIntrinsics pinhole;
  pinhole.width = 768;
  pinhole.height = 512;
  pinhole.params = {689.87, 691.04, 379.7975, 251.3275, 0, 0, 0, 0};
  CameraIntrinsics distorted;
  distorted.width = 1920;
  distorted.height = 1440;
  distorted.params = {1436.8, 1440.7, 959.25, 719.75, 0.074, -0.09, 1e-4, -2e-4};
  s.images.cameras = {pinhole, distorted};
  s.images.images = {{"a/0000.jpg", 768, 512, 0},
                     {"a/0001.jpg", 768, 512, 0},
                     {"b/0000.jpg", 1920, 1440, 1},
                     {"b/0001.jpg", 1920, 1440, 1}};
  const int counts[] = {300, 257, 411, 0};
  std::uniform_int_distribution<int> grid(0, 1900 * 256);
  std::uniform_real_distribution<float> scale(0.5f, 40.0f), angle(-3.14159f, 3.14159f);
  std::uniform_int_distribution<int> byte(0, 255);
  for (int i = 0; i < 4; ++i) {
    ImageFeatures f;
    f.keypoints.resize(counts[i], 4);
    f.descriptors.resize(counts[i], 128);
    for (int k = 0; k < counts[i]; ++k) {
      f.keypoints(k, 0) = grid(rng) / 256.0f;
      f.keypoints(k, 1) = grid(rng) / 256.0f;
      f.keypoints(k, 2) = scale(rng);
      f.keypoints(k, 3) = angle(rng);
      for (int d = 0; d < 128; ++d) f.descriptors(k, d) = static_cast<uint8_t>(byte(rng));
    }
    s.features.push_back(f);
  }
  const std::pair<int, int> pair_indices[] = {{0, 1}, {0, 2}, {1, 2}, {1, 3}, {2, 3}};
  const TwoViewConfig configs[] = {TwoViewConfig::kCalibrated, TwoViewConfig::kUncalibrated,
                                   TwoViewConfig::kPlanarOrPanoramic, TwoViewConfig::kUndefined,
                                   TwoViewConfig::kDegenerate};
  for (int p = 0; p < 5; ++p) {
    PairMatches pair;
    pair.image1 = pair_indices[p].first;
    pair.image2 = pair_indices[p].second;
    const int n1 = counts[pair.image1], n2 = counts[pair.image2];
    const int m = std::min(n1, n2) / 2;
    pair.matches.resize(m, 2);
    std::uniform_int_distribution<uint32_t> k1(0, std::max(n1, 1) - 1), k2(0, std::max(n2, 1) - 1);
    for (int r = 0; r < m; ++r) pair.matches.row(r) << k1(rng), k2(rng);
    pair.geometry.config = configs[p];
    if (m > 0) {
      pair.geometry.inlier_matches = pair.matches.topRows(m / 2);
      pair.geometry.F = RandomMatrix(rng);
      pair.geometry.E = RandomMatrix(rng);
      pair.geometry.H = RandomMatrix(rng);
      pair.geometry.cam2_from_cam1 =
          Rigid3(Eigen::Quaterniond(
                     Eigen::AngleAxisd(0.3 * (p + 1), Eigen::Vector3d(1, 2, 3).normalized())),
                 Eigen::Vector3d(0.1 * p, -0.7, 0.2));
    }
    s.pairs.push_back(pair);
  }
  return s;
}

// Sampson distance (px) of a correspondence under F.
double Sampson(const Eigen::Matrix3d& F, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector3d x1(a.x(), a.y(), 1), x2(b.x(), b.y(), 1);
  const Eigen::Vector3d fx1 = F * x1, ftx2 = F.transpose() * x2;
  return std::abs(x2.dot(fx1)) /
         std::sqrt(fx1.head<2>().squaredNorm() + ftx2.head<2>().squaredNorm());
}

void ExpectMatrixNear(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b, double relative) {
  EXPECT_LE((a - b).norm(), relative * std::max(1.0, b.norm())) << a << "\nvs\n" << b;
}

TEST(ColmapDatabase, PairIdsAreColmaps) {
  // Values read from a database written by COLMAP 3.8's exhaustive_matcher.
  EXPECT_EQ(ColmapPairId(1, 2), 2147483649u);
  EXPECT_EQ(ColmapPairId(2, 3), 4294967297u);
  EXPECT_EQ(ColmapPairId(2, 1), ColmapPairId(1, 2));
  uint32_t a = 0, b = 0;
  ColmapImageIdsFromPairId(ColmapPairId(17, 123456), &a, &b);
  EXPECT_EQ(a, 17u);
  EXPECT_EQ(b, 123456u);
}

TEST(ColmapDatabase, RoundTripIsLossless) {
  TempDir dir("colmapdb");
  const DatabaseScene s = MakeDatabaseScene();
  const std::string path = dir / "database.db";
  WriteColmapDatabase(path, s.images, s.features, s.pairs);
  const ColmapDatabase db = ReadColmapDatabase(path);

  ASSERT_EQ(db.images.images.size(), s.images.images.size());
  for (size_t i = 0; i < s.images.images.size(); ++i) {
    EXPECT_EQ(db.images.images[i].name, s.images.images[i].name);
    EXPECT_EQ(db.images.images[i].camera_index, s.images.images[i].camera_index);
    EXPECT_EQ(db.images.images[i].width, s.images.images[i].width);
    EXPECT_EQ(db.images.images[i].height, s.images.images[i].height);
  }
  ASSERT_EQ(db.images.cameras.size(), 2u);
  EXPECT_EQ(db.images.cameras[0], s.images.cameras[0]);
  EXPECT_EQ(db.images.cameras[1], s.images.cameras[1]);

  ASSERT_EQ(db.features.size(), s.features.size());
  for (size_t i = 0; i < s.features.size(); ++i) {
    EXPECT_EQ(db.features[i].keypoints, s.features[i].keypoints) << "image " << i;
    EXPECT_EQ(db.features[i].descriptors, s.features[i].descriptors) << "image " << i;
  }
  ASSERT_EQ(db.pairs.size(), s.pairs.size());
  for (size_t p = 0; p < s.pairs.size(); ++p) {
    const PairMatches& a = db.pairs[p];
    const PairMatches& b = s.pairs[p];
    EXPECT_EQ(a.image1, b.image1);
    EXPECT_EQ(a.image2, b.image2);
    EXPECT_EQ(a.matches, b.matches);
    EXPECT_EQ(a.geometry.inlier_matches, b.geometry.inlier_matches);
    EXPECT_EQ(a.geometry.config, b.geometry.config);
    EXPECT_EQ(a.geometry.E, b.geometry.E);
    EXPECT_EQ(a.geometry.cam2_from_cam1.rotation.coeffs(),
              b.geometry.cam2_from_cam1.rotation.coeffs());
    EXPECT_EQ(a.geometry.cam2_from_cam1.translation, b.geometry.cam2_from_cam1.translation);
    // F and H go through the pixel shift and back: exact up to double rounding.
    ExpectMatrixNear(a.geometry.F, b.geometry.F, 1e-14);
    ExpectMatrixNear(a.geometry.H, b.geometry.H, 1e-14);
  }
}

TEST(ColmapDatabase, KeypointShiftLosesAtMostOneUlp) {
  // Arbitrary float32 coordinates: x + 0.5 is exact unless it needs a bit more than x has (x < 1,
  // or x within 0.5 px under a power of two).
  TempDir dir("colmapdb");
  DatabaseScene s = MakeDatabaseScene();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-0.5f, 1919.5f);
  int exact = 0, total = 0;
  for (auto& f : s.features) {
    for (Eigen::Index k = 0; k < f.keypoints.rows(); ++k) {
      f.keypoints(k, 0) = u(rng);
      f.keypoints(k, 1) = u(rng);
    }
  }
  WriteColmapDatabase(dir / "database.db", s.images, s.features, s.pairs);
  const ColmapDatabase db = ReadColmapDatabase(dir / "database.db");
  for (size_t i = 0; i < s.features.size(); ++i) {
    for (Eigen::Index k = 0; k < s.features[i].keypoints.rows(); ++k) {
      for (int c = 0; c < 2; ++c) {
        const float x = s.features[i].keypoints(k, c);
        const float y = db.features[i].keypoints(k, c);
        const float shifted = x + 0.5f;
        EXPECT_LE(std::abs(y - x), std::nextafter(shifted, 1e9f) - shifted) << x;
        exact += y == x;
        ++total;
      }
    }
    ASSERT_EQ(db.features[i].keypoints.rows(), s.features[i].keypoints.rows());
    // No block of an empty matrix: Eigen offsets its null data pointer (undefined behaviour).
    if (s.features[i].keypoints.rows() == 0) continue;
    EXPECT_EQ(db.features[i].keypoints.rightCols(2), s.features[i].keypoints.rightCols(2));
  }
  EXPECT_GE(exact, 0.98 * total);
}

// A synthetic calibrated pair: F (OpenCV pixels) from the poses must, once exported, hold for the
// COLMAP-convention keypoints in the database, and the principal point must carry the shift.
TEST(ColmapDatabase, ExportShiftsKeypointsPrincipalPointAndFundamentalMatrix) {
  TempDir dir("colmapdb");
  ImageSet images;
  CameraIntrinsics k;
  k.width = 768;
  k.height = 512;
  k.params = {700, 690, 380, 250, 0, 0, 0, 0};
  images.cameras = {k};
  images.images = {{"0.jpg", 768, 512, 0}, {"1.jpg", 768, 512, 0}};
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.1, 1, 0.2).normalized())
                                .toRotationMatrix();  // cam2_from_cam1
  const Eigen::Vector3d t(-1, 0.6, 0.2);
  Eigen::Matrix3d K;
  K << 700, 0, 380, 0, 690, 250, 0, 0, 1;
  Eigen::Matrix3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  const Eigen::Matrix3d E = tx * R;
  const Eigen::Matrix3d F = K.inverse().transpose() * E * K.inverse();
  std::vector<ImageFeatures> features(2);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-2, 2), depth(4, 8);
  const int n = 50;
  for (auto& f : features) f.keypoints.resize(n, 4);
  PairMatches pair;
  pair.image1 = 0;
  pair.image2 = 1;
  pair.matches.resize(n, 2);
  for (int i = 0; i < n; ++i) {
    const double z = depth(rng);
    const Eigen::Vector2d xy = DrawVector2([&] { return u(rng); });
    const Eigen::Vector3d x1(xy.x(), xy.y(), z);
    const Eigen::Vector3d x2 = R * x1 + t;
    const Eigen::Vector3d p1 = K * x1 / x1.z(), p2 = K * x2 / x2.z();
    features[0].keypoints.row(i) << float(p1.x()), float(p1.y()), 2.0f, 0.0f;
    features[1].keypoints.row(i) << float(p2.x()), float(p2.y()), 2.0f, 0.0f;
    pair.matches.row(i) << i, i;
  }
  pair.geometry.config = TwoViewConfig::kCalibrated;
  pair.geometry.F = F;
  pair.geometry.E = E;
  pair.geometry.inlier_matches = pair.matches;
  const std::string path = dir / "database.db";
  WriteColmapDatabase(path, images, features, {pair});

  const std::string f_blob = SqlBlob(path, "SELECT F FROM two_view_geometries");
  ASSERT_EQ(f_blob.size(), 72u);
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> f_colmap;
  std::memcpy(f_colmap.data(), f_blob.data(), 72);
  std::string kp[2] = {SqlBlob(path, "SELECT data FROM keypoints WHERE image_id = 1"),
                       SqlBlob(path, "SELECT data FROM keypoints WHERE image_id = 2")};
  ASSERT_EQ(kp[0].size(), n * 4 * sizeof(float));
  const float* k1 = reinterpret_cast<const float*>(kp[0].data());
  const float* k2 = reinterpret_cast<const float*>(kp[1].data());
  // Sampson distances (px) in COLMAP's pixels: zero up to float32 keypoint rounding, and
  // clearly not zero when the keypoints are left in OpenCV's pixels (the check is not vacuous).
  double shifted = 0, unshifted = 0;
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(k1[4 * i], features[0].keypoints(i, 0) + 0.5f);
    EXPECT_EQ(k2[4 * i + 1], features[1].keypoints(i, 1) + 0.5f);
    const Eigen::Vector2d a(k1[4 * i], k1[4 * i + 1]), b(k2[4 * i], k2[4 * i + 1]);
    const Eigen::Vector2d half(0.5, 0.5);
    shifted = std::max(shifted, Sampson(f_colmap, a, b));
    unshifted += Sampson(f_colmap, a - half, b - half) / n;
  }
  EXPECT_LT(shifted, 1e-3);
  EXPECT_GT(unshifted, 10 * shifted);
  EXPECT_GT(unshifted, 0.01);
  const std::string params = SqlBlob(path, "SELECT params FROM cameras");
  ASSERT_EQ(params.size(), 4 * sizeof(double));
  const double* p = reinterpret_cast<const double*>(params.data());
  EXPECT_EQ(p[2], 380.5);
  EXPECT_EQ(p[3], 250.5);
}

TEST(ColmapDatabase, OpencvCameraModelOnRequest) {
  TempDir dir("colmapdb");
  const DatabaseScene s = MakeDatabaseScene();
  WriteColmapDatabase(dir / "database.db", s.images, s.features, s.pairs, "OPENCV");
  const std::string params = SqlBlob(dir / "database.db", "SELECT params FROM cameras");
  EXPECT_EQ(params.size(), 8 * sizeof(double));
  const ColmapDatabase db = ReadColmapDatabase(dir / "database.db");
  EXPECT_EQ(db.images.cameras[0], s.images.cameras[0]);
  EXPECT_NE(InputErrorOf([&] {
              WriteColmapDatabase(dir / "p.db", s.images, s.features, s.pairs, "PINHOLE");
            }).find("distortion"),
            std::string::npos);
  EXPECT_NE(InputErrorOf([&] {
              WriteColmapDatabase(dir / "p.db", s.images, s.features, s.pairs, "FOV");
            }).find("'FOV'"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "p.db"));
}

// COLMAP's own layout: 6-column affine keypoints (feature_extractor), 2-column locations, and
// image ids that do not follow name order, so the pair must be turned around on import.
TEST(ColmapDatabase, ImportsAffineKeypointsAndSwappedPairs) {
  TempDir dir("colmapdb");
  const DatabaseScene s = MakeDatabaseScene();
  const std::string path = dir / "database.db";
  WriteColmapDatabase(path, s.images, s.features, s.pairs);
  // Image ids 1 and 2 exchange names: "a/0000.jpg" becomes id 2 (with id 2's keypoints).
  Sql(path,
      "UPDATE images SET name = 'tmp' WHERE image_id = 1;"
      "UPDATE images SET name = 'a/0000.jpg' WHERE image_id = 2;"
      "UPDATE images SET name = 'a/0001.jpg' WHERE image_id = 1;");
  // Image id 3 (b/0000.jpg): keypoints rewritten as COLMAP's 6-column affine shape.
  const ImageFeatures& f3 = s.features[2];
  std::string blob(f3.keypoints.rows() * 6 * sizeof(float), '\0');
  float* a = reinterpret_cast<float*>(blob.data());
  for (Eigen::Index k = 0; k < f3.keypoints.rows(); ++k) {
    const float scale = f3.keypoints(k, 2), angle = f3.keypoints(k, 3);
    const float row[6] = {f3.keypoints(k, 0) + 0.5f, f3.keypoints(k, 1) + 0.5f,
                          scale * std::cos(angle),   -scale * std::sin(angle),
                          scale * std::sin(angle),   scale * std::cos(angle)};
    std::memcpy(a + 6 * k, row, sizeof(row));
  }
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    sqlite3_stmt* stmt = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE keypoints SET cols = 6, data = ? WHERE image_id = 3",
                                 -1, &stmt, nullptr),
              SQLITE_OK);
    sqlite3_bind_blob(stmt, 1, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
    ASSERT_EQ(sqlite3_step(stmt), SQLITE_DONE);
    sqlite3_finalize(stmt);
    sqlite3_close(db);
  }
  const ColmapDatabase db = ReadColmapDatabase(path);
  // Names stay sorted; features follow the names.
  EXPECT_EQ(db.images.images[0].name, "a/0000.jpg");
  EXPECT_EQ(db.features[0].keypoints, s.features[1].keypoints);
  EXPECT_EQ(db.features[1].keypoints, s.features[0].keypoints);
  for (Eigen::Index k = 0; k < f3.keypoints.rows(); ++k) {
    EXPECT_NEAR(db.features[2].keypoints(k, 2), f3.keypoints(k, 2), 1e-4 * f3.keypoints(k, 2));
    EXPECT_NEAR(std::remainder(db.features[2].keypoints(k, 3) - f3.keypoints(k, 3), 2 * M_PI), 0,
                1e-5);
    EXPECT_EQ(db.features[2].keypoints(k, 0), f3.keypoints(k, 0));
  }
  // The pair of ids (1, 2) is now (a/0001, a/0000): swapped into (0, 1).
  const PairMatches& original = s.pairs[0];
  const PairMatches& swapped = db.pairs[0];
  ASSERT_EQ(swapped.image1, 0);
  ASSERT_EQ(swapped.image2, 1);
  EXPECT_EQ(swapped.matches.col(0), original.matches.col(1));
  EXPECT_EQ(swapped.matches.col(1), original.matches.col(0));
  EXPECT_EQ(swapped.geometry.inlier_matches.col(0), original.geometry.inlier_matches.col(1));
  EXPECT_EQ(swapped.geometry.E, Eigen::Matrix3d(original.geometry.E.transpose()));
  ExpectMatrixNear(swapped.geometry.F, original.geometry.F.transpose(), 1e-14);
  ExpectMatrixNear(swapped.geometry.H, original.geometry.H.inverse(), 1e-12);
  const Rigid3 inverse = original.geometry.cam2_from_cam1.Inverse();
  EXPECT_LT(swapped.geometry.cam2_from_cam1.rotation.angularDistance(inverse.rotation), 1e-12);
  EXPECT_LT((swapped.geometry.cam2_from_cam1.translation - inverse.translation).norm(), 1e-12);
  // Pairs not involving the swapped ids are untouched: (a/0001 = id 1, b/0000 = id 3) is (1, 2).
  EXPECT_EQ(db.pairs[2].image1, 0);
  EXPECT_EQ(db.pairs[3].image1, 1);
  EXPECT_EQ(db.pairs[3].matches, s.pairs[1].matches);

  // Two-column keypoints: locations with COLMAP's default scale 1 and orientation 0.
  Sql(path,
      "UPDATE keypoints SET cols = 2, rows = 1, data = x'0000C03F0000C03F' WHERE image_id = 4;");
  const ColmapDatabase two = ReadColmapDatabase(path);
  ASSERT_EQ(two.features[3].keypoints.rows(), 1);
  EXPECT_EQ(two.features[3].keypoints(0, 0), 1.0f);
  EXPECT_EQ(two.features[3].keypoints(0, 2), 1.0f);
  EXPECT_EQ(two.features[3].keypoints(0, 3), 0.0f);
}

TEST(ColmapDatabase, ForeignOrCorruptFilesNameTheProblem) {
  TempDir dir("colmapdb");
  EXPECT_NE(
      InputErrorOf([&] { ReadColmapDatabase(dir / "missing.db"); }).find("missing.db: no such"),
      std::string::npos);
  {
    std::ofstream(dir / "text.db") << "this is not an SQLite file, it is long enough to have a "
                                      "header that SQLite would check: 0123456789abcdef0123";
  }
  const std::string not_sqlite = InputErrorOf([&] { ReadColmapDatabase(dir / "text.db"); });
  EXPECT_NE(not_sqlite.find("text.db"), std::string::npos) << not_sqlite;
  EXPECT_NE(not_sqlite.find("not a readable SQLite database"), std::string::npos) << not_sqlite;

  Sql(dir / "other.db", "CREATE TABLE images (id INTEGER); CREATE TABLE notes (t TEXT);");
  const std::string other = InputErrorOf([&] { ReadColmapDatabase(dir / "other.db"); });
  EXPECT_NE(other.find("not a COLMAP database: missing table(s) cameras, keypoints"),
            std::string::npos)
      << other;
  EXPECT_NE(other.find("tables found: images, notes"), std::string::npos) << other;

  const DatabaseScene s = MakeDatabaseScene();
  const std::string path = dir / "database.db";
  WriteColmapDatabase(path, s.images, s.features, s.pairs);
  const std::string copy = dir / "corrupt.db";
  fs::copy_file(path, copy);
  Sql(copy, "UPDATE keypoints SET rows = rows + 1 WHERE image_id = 2;");
  const std::string blob_error = InputErrorOf([&] { ReadColmapDatabase(copy); });
  EXPECT_NE(blob_error.find("corrupt.db"), std::string::npos) << blob_error;
  EXPECT_NE(blob_error.find("table keypoints, image_id 2 (a/0001.jpg)"), std::string::npos)
      << blob_error;
  EXPECT_NE(blob_error.find("bytes"), std::string::npos) << blob_error;

  fs::copy_file(path, copy, fs::copy_options::overwrite_existing);
  // Image 2 keeps a single keypoint: matches of pair (1, 2) now point past it.
  Sql(copy,
      "UPDATE keypoints SET rows = 1, data = substr(data, 1, 16) WHERE image_id = 2;"
      "UPDATE descriptors SET rows = 0, data = x'' WHERE image_id = 2;");
  const std::string range_error = InputErrorOf([&] { ReadColmapDatabase(copy); });
  EXPECT_NE(range_error.find("table matches, pair_id 2147483649"), std::string::npos)
      << range_error;
  EXPECT_NE(range_error.find("out of range"), std::string::npos) << range_error;

  fs::copy_file(path, copy, fs::copy_options::overwrite_existing);
  Sql(copy, "UPDATE cameras SET model = 42 WHERE camera_id = 2;");
  const std::string model_error = InputErrorOf([&] { ReadColmapDatabase(copy); });
  EXPECT_NE(model_error.find("table cameras, camera_id 2: unknown camera model id 42"),
            std::string::npos)
      << model_error;

  fs::copy_file(path, copy, fs::copy_options::overwrite_existing);
  Sql(copy, "UPDATE images SET camera_id = 9 WHERE image_id = 4;");
  const std::string camera_error = InputErrorOf([&] { ReadColmapDatabase(copy); });
  EXPECT_NE(camera_error.find("b/0001.jpg): refers to missing camera 9"), std::string::npos)
      << camera_error;
}

TEST(ColmapDatabase, ExportIsAtomicAndChecksItsInput) {
  TempDir dir("colmapdb");
  const DatabaseScene s = MakeDatabaseScene();
  const std::string path = dir / "database.db";
  WriteColmapDatabase(path, s.images, s.features, s.pairs);
  const auto size = fs::file_size(path);

  // Bad input: nothing is written and the existing database survives.
  std::vector<PairMatches> bad = s.pairs;
  bad[0].matches(0, 1) = 100000;
  const std::string error =
      InputErrorOf([&] { WriteColmapDatabase(path, s.images, s.features, bad); });
  EXPECT_NE(error.find("pair 0_1 (a/0000.jpg / a/0001.jpg): a match refers to a keypoint beyond"),
            std::string::npos)
      << error;
  std::vector<ImageFeatures> too_few(s.features.begin(), s.features.end() - 1);
  EXPECT_NE(InputErrorOf([&] {
              WriteColmapDatabase(path, s.images, too_few, s.pairs);
            }).find("3 feature sets for 4 images"),
            std::string::npos);
  EXPECT_EQ(fs::file_size(path), size);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1);

  // Rewriting replaces the database (no rows are appended to the old one).
  WriteColmapDatabase(path, s.images, s.features, {s.pairs[0]});
  EXPECT_EQ(ReadColmapDatabase(path).pairs.size(), 1u);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1);
}

}  // namespace
}  // namespace raytime

#include "formats/colmap_database.h"

#include <sqlite3.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <set>
#include <type_traits>
#include <utility>

#include "core/atomic_file.h"
#include "core/error.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

// COLMAP 3.8's camera model ids (the `model` column), by position.
constexpr const char* kColmapModelNames[] = {"SIMPLE_PINHOLE",
                                             "PINHOLE",
                                             "SIMPLE_RADIAL",
                                             "RADIAL",
                                             "OPENCV",
                                             "OPENCV_FISHEYE",
                                             "FULL_OPENCV",
                                             "FOV",
                                             "SIMPLE_RADIAL_FISHEYE",
                                             "RADIAL_FISHEYE",
                                             "THIN_PRISM_FISHEYE"};
constexpr int kNumColmapModels = sizeof(kColmapModelNames) / sizeof(kColmapModelNames[0]);

int ColmapModelId(const std::string& name) {
  for (int id = 0; id < kNumColmapModels; ++id) {
    if (name == kColmapModelNames[id]) return id;
  }
  return -1;
}

// COLMAP 3.8's schema, statement for statement as src/base/database.cc creates it, so a
// database we write is indistinguishable from one COLMAP made.
constexpr const char* kSchema[] = {
    "CREATE TABLE IF NOT EXISTS cameras"
    "   (camera_id            INTEGER  PRIMARY KEY AUTOINCREMENT  NOT NULL,"
    "    model                INTEGER                             NOT NULL,"
    "    width                INTEGER                             NOT NULL,"
    "    height               INTEGER                             NOT NULL,"
    "    params               BLOB,"
    "    prior_focal_length   INTEGER                             NOT NULL);",
    "CREATE TABLE IF NOT EXISTS images"
    "   (image_id   INTEGER  PRIMARY KEY AUTOINCREMENT  NOT NULL,"
    "    name       TEXT                                NOT NULL UNIQUE,"
    "    camera_id  INTEGER                             NOT NULL,"
    "    prior_qw   REAL,"
    "    prior_qx   REAL,"
    "    prior_qy   REAL,"
    "    prior_qz   REAL,"
    "    prior_tx   REAL,"
    "    prior_ty   REAL,"
    "    prior_tz   REAL,"
    "CONSTRAINT image_id_check CHECK(image_id >= 0 and image_id < 2147483647),"
    "FOREIGN KEY(camera_id) REFERENCES cameras(camera_id));"
    "CREATE UNIQUE INDEX IF NOT EXISTS index_name ON images(name);",
    "CREATE TABLE IF NOT EXISTS keypoints"
    "   (image_id  INTEGER  PRIMARY KEY  NOT NULL,"
    "    rows      INTEGER               NOT NULL,"
    "    cols      INTEGER               NOT NULL,"
    "    data      BLOB,"
    "FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE);",
    "CREATE TABLE IF NOT EXISTS descriptors"
    "   (image_id  INTEGER  PRIMARY KEY  NOT NULL,"
    "    rows      INTEGER               NOT NULL,"
    "    cols      INTEGER               NOT NULL,"
    "    data      BLOB,"
    "FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE);",
    "CREATE TABLE IF NOT EXISTS matches"
    "   (pair_id  INTEGER  PRIMARY KEY  NOT NULL,"
    "    rows     INTEGER               NOT NULL,"
    "    cols     INTEGER               NOT NULL,"
    "    data     BLOB);",
    "CREATE TABLE IF NOT EXISTS two_view_geometries"
    "   (pair_id  INTEGER  PRIMARY KEY  NOT NULL,"
    "    rows     INTEGER               NOT NULL,"
    "    cols     INTEGER               NOT NULL,"
    "    data     BLOB,"
    "    config   INTEGER               NOT NULL,"
    "    F        BLOB,"
    "    E        BLOB,"
    "    H        BLOB,"
    "    qvec     BLOB,"
    "    tvec     BLOB);",
    // COLMAP 3.8 stamps its version here and migrates older files on open; ours need nothing.
    "PRAGMA user_version = 3800;",
};

constexpr const char* kRequiredTables[] = {"cameras",     "images",  "keypoints",
                                           "descriptors", "matches", "two_view_geometries"};

// One open connection; every failure becomes an InputError naming the file.
class Sqlite {
 public:
  Sqlite(const std::string& path, int flags) : path_(path) {
    if (sqlite3_open_v2(path.c_str(), &db_, flags, nullptr) != SQLITE_OK) {
      const std::string message = db_ ? sqlite3_errmsg(db_) : "out of memory";
      sqlite3_close(db_);
      ThrowInput(path, 0, "cannot open as an SQLite database: " + message);
    }
  }
  ~Sqlite() { sqlite3_close(db_); }
  Sqlite(const Sqlite&) = delete;
  Sqlite& operator=(const Sqlite&) = delete;

  sqlite3* get() const { return db_; }
  const std::string& path() const { return path_; }

  [[noreturn]] void Fail(const std::string& what) const {
    ThrowInput(path_, 0, what + ": " + sqlite3_errmsg(db_));
  }
  void Exec(const std::string& sql, const std::string& what) const {
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr) != SQLITE_OK) Fail(what);
  }

 private:
  std::string path_;
  sqlite3* db_ = nullptr;
};

class Statement {
 public:
  Statement(const Sqlite& db, const std::string& sql) : db_(db) {
    if (sqlite3_prepare_v2(db.get(), sql.c_str(), -1, &stmt_, nullptr) != SQLITE_OK) {
      db.Fail("cannot prepare '" + sql + "'");
    }
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  // True while rows come; throws on an error (e.g. SQLITE_NOTADB, SQLITE_CORRUPT).
  bool Step(const std::string& what) {
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    db_.Fail(what);
  }
  void Reset() {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }

  int64_t Int(int col) const { return sqlite3_column_int64(stmt_, col); }
  std::string Text(int col) const {
    const auto* text = sqlite3_column_text(stmt_, col);
    return text ? reinterpret_cast<const char*>(text) : "";
  }
  bool IsNull(int col) const { return sqlite3_column_type(stmt_, col) == SQLITE_NULL; }
  // Blob bytes (empty for NULL).
  std::string Blob(int col) const {
    const void* data = sqlite3_column_blob(stmt_, col);
    const int size = sqlite3_column_bytes(stmt_, col);
    return data ? std::string(static_cast<const char*>(data), size) : std::string();
  }

  void BindInt(int index, int64_t value) { Check(sqlite3_bind_int64(stmt_, index, value)); }
  void BindText(int index, const std::string& value) {
    Check(sqlite3_bind_text(stmt_, index, value.c_str(), static_cast<int>(value.size()),
                            SQLITE_TRANSIENT));
  }
  void BindBlob(int index, const void* data, size_t bytes) {
    // A zero-length blob, not NULL, for empty matrices: COLMAP reads both as empty.
    Check(sqlite3_bind_blob64(stmt_, index, bytes ? data : "", bytes, SQLITE_TRANSIENT));
  }
  void BindNull(int index) { Check(sqlite3_bind_null(stmt_, index)); }

 private:
  void Check(int rc) const {
    if (rc != SQLITE_OK) db_.Fail("cannot bind a value");
  }
  const Sqlite& db_;
  sqlite3_stmt* stmt_ = nullptr;
};

// A row-major matrix blob (keypoints, descriptors, matches) checked against rows x cols.
template <typename Matrix>
Matrix ReadMatrixBlob(const Sqlite& db, const Statement& stmt, int rows_col,
                      const std::string& where) {
  using Scalar = typename Matrix::Scalar;
  constexpr int64_t kFixedCols = Matrix::ColsAtCompileTime;  // Eigen::Dynamic (< 0) or fixed
  const int64_t rows = stmt.Int(rows_col);
  const int64_t cols = stmt.Int(rows_col + 1);
  const std::string blob = stmt.Blob(rows_col + 2);
  if (rows < 0 || cols < 0 || (kFixedCols > 0 && rows > 0 && cols != kFixedCols)) {
    ThrowInput(
        db.path(), 0,
        where + ": shape " + std::to_string(rows) + " x " + std::to_string(cols) + " is invalid" +
            (kFixedCols > 0 ? " (expected " + std::to_string(kFixedCols) + " columns)" : ""));
  }
  // A shape whose byte count wraps around 2^64 could otherwise match the blob and size the matrix.
  const bool too_large = cols != 0 && uint64_t(rows) > std::numeric_limits<uint64_t>::max() /
                                                           sizeof(Scalar) / uint64_t(cols);
  const uint64_t expected = too_large ? 0 : uint64_t(rows) * uint64_t(cols) * sizeof(Scalar);
  if (too_large || blob.size() != expected) {
    ThrowInput(db.path(), 0,
               where + ": data holds " + std::to_string(blob.size()) + " bytes, but rows " +
                   std::to_string(rows) + " x cols " + std::to_string(cols) + " x " +
                   std::to_string(sizeof(Scalar)) +
                   " bytes = " + (too_large ? "more than 2^64" : std::to_string(expected)) +
                   " (corrupt database?)");
  }
  Matrix m(rows, kFixedCols > 0 ? kFixedCols : cols);
  if (!blob.empty()) std::memcpy(m.data(), blob.data(), blob.size());
  return m;
}

// F, E, H: row-major float64 3x3 (COLMAP transposes its column-major Eigen matrices before
// writing); an empty blob is the zero matrix, as COLMAP reads it.
Eigen::Matrix3d ReadMatrix3Blob(const Sqlite& db, const Statement& stmt, int col,
                                const std::string& where) {
  const std::string blob = stmt.Blob(col);
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> m = Eigen::Matrix3d::Zero();
  if (blob.empty()) return m;
  if (blob.size() != sizeof(double) * 9) {
    ThrowInput(db.path(), 0,
               where + ": holds " + std::to_string(blob.size()) +
                   " bytes, expected 72 (3 x 3 "
                   "float64)");
  }
  std::memcpy(m.data(), blob.data(), blob.size());
  return m;
}

template <int N>
Eigen::Matrix<double, N, 1> ReadVectorBlob(const Sqlite& db, const Statement& stmt, int col,
                                           const std::string& where) {
  const std::string blob = stmt.Blob(col);
  Eigen::Matrix<double, N, 1> v = Eigen::Matrix<double, N, 1>::Zero();
  if (blob.empty()) return v;
  if (blob.size() != sizeof(double) * N) {
    ThrowInput(db.path(), 0,
               where + ": holds " + std::to_string(blob.size()) + " bytes, expected " +
                   std::to_string(sizeof(double) * N) + " (" + std::to_string(N) + " float64)");
  }
  std::memcpy(v.data(), blob.data(), blob.size());
  return v;
}

// raytime pixel (OpenCV, centre of the top-left pixel at 0) -> COLMAP pixel (at 0.5).
Eigen::Matrix3d ColmapFromOpenCvPixel() {
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();
  s(0, 2) = 0.5;
  s(1, 2) = 0.5;
  return s;
}
Eigen::Matrix3d OpenCvFromColmapPixel() {
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();
  s(0, 2) = -0.5;
  s(1, 2) = -0.5;
  return s;
}

// x2^T F x1 = 0 and x2 ~ H x1 hold in the pixel convention of the matrices; with x_b = S x_a,
// F_b = S^-T F_a S^-1 and H_b = S H_a S^-1. Zero (unestimated) matrices stay zero.
Eigen::Matrix3d ConvertF(const Eigen::Matrix3d& f, const Eigen::Matrix3d& s_inv) {
  return s_inv.transpose() * f * s_inv;
}
Eigen::Matrix3d ConvertH(const Eigen::Matrix3d& h, const Eigen::Matrix3d& s,
                         const Eigen::Matrix3d& s_inv) {
  return s * h * s_inv;
}

std::string PairName(const std::string& a, const std::string& b) { return a + " / " + b; }

void CheckTables(const Sqlite& db) {
  std::set<std::string> tables;
  // The first read is where SQLite notices a file that is not a database at all.
  sqlite3_stmt* raw = nullptr;
  if (sqlite3_prepare_v2(db.get(), "SELECT name FROM sqlite_master WHERE type = 'table'", -1, &raw,
                         nullptr) != SQLITE_OK) {
    db.Fail("not a readable SQLite database (COLMAP database.db expected)");
  }
  sqlite3_finalize(raw);
  Statement stmt(db, "SELECT name FROM sqlite_master WHERE type = 'table'");
  while (stmt.Step("not a readable SQLite database (COLMAP database.db expected)")) {
    tables.insert(stmt.Text(0));
  }
  std::vector<std::string> missing;
  for (const char* table : kRequiredTables) {
    if (!tables.count(table)) missing.push_back(table);
  }
  if (missing.empty()) return;
  std::string missing_list, found_list;
  for (const auto& t : missing) missing_list += (missing_list.empty() ? "" : ", ") + t;
  for (const auto& t : tables) found_list += (found_list.empty() ? "" : ", ") + t;
  ThrowInput(db.path(), 0,
             "not a COLMAP database: missing table(s) " + missing_list +
                 " (tables found: " + (found_list.empty() ? "none" : found_list) + ")");
}

std::set<std::string> Columns(const Sqlite& db, const std::string& table) {
  std::set<std::string> columns;
  Statement stmt(db, "PRAGMA table_info(" + table + ")");
  while (stmt.Step("cannot list the columns of " + table)) columns.insert(stmt.Text(1));
  return columns;
}

ImageFeatures FeaturesFromColmapKeypoints(
    const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& blob) {
  ImageFeatures f;
  f.keypoints.resize(blob.rows(), 4);
  for (Eigen::Index i = 0; i < blob.rows(); ++i) {
    f.keypoints(i, 0) = static_cast<float>(double(blob(i, 0)) - 0.5);
    f.keypoints(i, 1) = static_cast<float>(double(blob(i, 1)) - 0.5);
    if (blob.cols() == 4) {
      f.keypoints(i, 2) = blob(i, 2);
      f.keypoints(i, 3) = blob(i, 3);
    } else if (blob.cols() == 6) {
      // COLMAP's FeatureKeypoint::ComputeScale (mean of the two axis scales) and
      // ComputeOrientation of the affine shape [a11 a12; a21 a22].
      const float a11 = blob(i, 2), a12 = blob(i, 3), a21 = blob(i, 4), a22 = blob(i, 5);
      f.keypoints(i, 2) =
          0.5f * (std::sqrt(a11 * a11 + a21 * a21) + std::sqrt(a12 * a12 + a22 * a22));
      f.keypoints(i, 3) = std::atan2(a21, a11);
    } else {
      // Two columns: location only (COLMAP's FeatureKeypoint(x, y) has scale 1, orientation 0).
      f.keypoints(i, 2) = 1.0f;
      f.keypoints(i, 3) = 0.0f;
    }
  }
  return f;
}

}  // namespace

uint64_t ColmapPairId(uint32_t image_id1, uint32_t image_id2) {
  if (image_id1 > image_id2) std::swap(image_id1, image_id2);
  return uint64_t(image_id1) * kColmapMaxNumImages + image_id2;
}

void ColmapImageIdsFromPairId(uint64_t pair_id, uint32_t* image_id1, uint32_t* image_id2) {
  *image_id2 = static_cast<uint32_t>(pair_id % kColmapMaxNumImages);
  *image_id1 = static_cast<uint32_t>((pair_id - *image_id2) / kColmapMaxNumImages);
}

ColmapCamera ColmapCameraWithModel(const CameraIntrinsics& intrinsics, uint32_t camera_id,
                                   const std::string& camera_model) {
  ColmapCamera camera = ColmapFromIntrinsics(intrinsics, camera_id);
  if (camera_model.empty() || camera_model == camera.model) return camera;
  if (camera_model == "OPENCV") {
    // PINHOLE -> OPENCV: same fx, fy, cx, cy, zero distortion that BA may then refine.
    camera.model = "OPENCV";
    camera.params.resize(8, 0.0);
    return camera;
  }
  if (camera_model == "PINHOLE") {
    throw InputError("camera " + std::to_string(camera_id) +
                     " has distortion, which COLMAP's PINHOLE model cannot hold: use OPENCV");
  }
  throw InputError("COLMAP camera model '" + camera_model +
                   "' is not supported for export (PINHOLE or OPENCV)");
}

namespace {

// The table cameras by id (only those an image uses are converted later: an unused camera of an
// unsupported model is no reason to fail, as in FromColmapModel).
std::map<int64_t, ColmapCamera> ReadDatabaseCameras(const Sqlite& db, const std::string& path) {
  std::map<int64_t, ColmapCamera> cameras;
  Statement stmt(db, "SELECT camera_id, model, width, height, params FROM cameras");
  while (stmt.Step("cannot read table cameras")) {
    ColmapCamera camera;
    const int64_t id = stmt.Int(0);
    const int64_t model = stmt.Int(1);
    const std::string where = "table cameras, camera_id " + std::to_string(id);
    if (id <= 0 || id > std::numeric_limits<uint32_t>::max()) {
      ThrowInput(path, 0, where + ": invalid camera id");
    }
    if (model < 0 || model >= kNumColmapModels) {
      ThrowInput(path, 0, where + ": unknown camera model id " + std::to_string(model));
    }
    if (stmt.Int(2) <= 0 || stmt.Int(3) <= 0) ThrowInput(path, 0, where + ": invalid size");
    camera.camera_id = static_cast<uint32_t>(id);
    camera.model = kColmapModelNames[model];
    camera.width = static_cast<uint64_t>(stmt.Int(2));
    camera.height = static_cast<uint64_t>(stmt.Int(3));
    const std::string params = stmt.Blob(4);
    if (params.size() % sizeof(double) != 0) {
      ThrowInput(path, 0,
                 where + ": params blob of " + std::to_string(params.size()) +
                     " bytes is not a list of float64");
    }
    camera.params.resize(params.size() / sizeof(double));
    if (!params.empty()) std::memcpy(camera.params.data(), params.data(), params.size());
    cameras[id] = camera;
  }
  return cameras;
}

// The table images, sorted by name, into out->images (their cameras converted once each, in
// order of first use); *image_index maps COLMAP's image id to the index.
void ReadDatabaseImages(const Sqlite& db, const std::string& path,
                        const std::map<int64_t, ColmapCamera>& cameras, ColmapDatabase* out,
                        std::map<int64_t, int>* image_index) {
  struct DbImage {
    int64_t image_id;
    std::string name;
    int64_t camera_id;
  };
  std::vector<DbImage> db_images;
  {
    Statement stmt(db, "SELECT image_id, name, camera_id FROM images");
    while (stmt.Step("cannot read table images")) {
      db_images.push_back({stmt.Int(0), stmt.Text(1), stmt.Int(2)});
    }
  }
  std::sort(db_images.begin(), db_images.end(),
            [](const DbImage& a, const DbImage& b) { return a.name < b.name; });
  std::map<int64_t, int> camera_index;
  for (const DbImage& image : db_images) {
    const std::string where = "table images, image_id " + std::to_string(image.image_id);
    if (image.name.empty()) ThrowInput(path, 0, where + ": empty name");
    if (!out->images.images.empty() && out->images.images.back().name == image.name) {
      ThrowInput(path, 0, where + ": two images are named " + image.name);
    }
    const auto camera = cameras.find(image.camera_id);
    if (camera == cameras.end()) {
      ThrowInput(path, 0,
                 where + " (" + image.name + "): refers to missing camera " +
                     std::to_string(image.camera_id));
    }
    auto [it, inserted] = camera_index.emplace(image.camera_id, 0);
    if (inserted) {
      try {
        out->images.cameras.push_back(IntrinsicsFromColmap(camera->second));
      } catch (const InputError& e) {
        ThrowInput(path, 0, std::string("table cameras: ") + e.what());
      }
      it->second = static_cast<int>(out->images.cameras.size()) - 1;
    }
    const CameraIntrinsics& intrinsics = out->images.cameras[it->second];
    (*image_index)[image.image_id] = static_cast<int>(out->images.images.size());
    out->images.images.push_back({image.name, intrinsics.width, intrinsics.height, it->second});
  }
}

using MatchMatrix = Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor>;

// The tables after cameras and images, read into `out` with every row checked against what is
// already read: keypoints and descriptors per image, then the pairs, the union of `matches` and
// `two_view_geometries`, keyed by (index1, index2) in name order.
class DatabaseTablesReader {
 public:
  DatabaseTablesReader(const Sqlite& db, const std::string& path,
                       const std::map<int64_t, int>& image_index, ColmapDatabase* out)
      : db_(db), path_(path), image_index_(image_index), out_(out) {}

  void ReadKeypoints() {
    out_->features.resize(out_->images.images.size());
    for (auto& f : out_->features) f.keypoints.resize(0, 4);
    Statement stmt(db_, "SELECT image_id, rows, cols, data FROM keypoints");
    while (stmt.Step("cannot read table keypoints")) {
      const int64_t id = stmt.Int(0);
      const std::string where = "table keypoints, image_id " + std::to_string(id);
      const int index = ImageIndex(id, where);
      using Blob = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
      const Blob blob = ReadMatrixBlob<Blob>(db_, stmt, 1, where + " (" + NameOf(id) + ")");
      if (blob.rows() > 0 && blob.cols() != 2 && blob.cols() != 4 && blob.cols() != 6) {
        ThrowInput(path_, 0,
                   where + " (" + NameOf(id) + "): " + std::to_string(blob.cols()) +
                       " columns; COLMAP keypoints have 2, 4 or 6");
      }
      out_->features[index] = FeaturesFromColmapKeypoints(blob);
    }
  }

  void ReadDescriptors() {
    Statement stmt(db_, "SELECT image_id, rows, cols, data FROM descriptors");
    while (stmt.Step("cannot read table descriptors")) {
      const int64_t id = stmt.Int(0);
      const std::string where = "table descriptors, image_id " + std::to_string(id);
      ImageFeatures& f = out_->features[ImageIndex(id, where)];
      f.descriptors = ReadMatrixBlob<std::decay_t<decltype(f.descriptors)>>(
          db_, stmt, 1, where + " (" + NameOf(id) + ")");
      if (f.descriptors.rows() != 0 && f.descriptors.rows() != f.keypoints.rows()) {
        ThrowInput(path_, 0,
                   where + " (" + NameOf(id) + "): " + std::to_string(f.descriptors.rows()) +
                       " descriptors for " + std::to_string(f.keypoints.rows()) + " keypoints");
      }
    }
  }

  void ReadMatches() {
    Statement stmt(db_, "SELECT pair_id, rows, cols, data FROM matches");
    while (stmt.Step("cannot read table matches")) {
      bool swapped = false;
      std::string where;
      PairMatches& pair = Resolve(stmt.Int(0), "matches", &swapped, &where);
      pair.matches =
          CheckAndOrient(ReadMatrixBlob<MatchMatrix>(db_, stmt, 1, where), pair, swapped, where);
    }
  }

  void ReadTwoViewGeometries() {
    // Databases older than COLMAP 3.5 lack some geometry columns; they read as zero.
    const std::set<std::string> columns = Columns(db_, "two_view_geometries");
    std::string select = "SELECT pair_id, rows, cols, data, config";
    for (const char* column : {"F", "E", "H", "qvec", "tvec"}) {
      select += columns.count(column) ? std::string(", ") + column : ", NULL";
    }
    Statement stmt(db_, select + " FROM two_view_geometries");
    while (stmt.Step("cannot read table two_view_geometries")) {
      bool swapped = false;
      std::string where;
      PairMatches& pair = Resolve(stmt.Int(0), "two_view_geometries", &swapped, &where);
      pair.geometry.inlier_matches =
          CheckAndOrient(ReadMatrixBlob<MatchMatrix>(db_, stmt, 1, where), pair, swapped, where);
      ReadGeometry(stmt, swapped, where, &pair.geometry);
    }
  }

  std::vector<PairMatches> TakePairs() {
    std::vector<PairMatches> out;
    out.reserve(pairs_.size());
    for (auto& [key, pair] : pairs_) out.push_back(std::move(pair));
    return out;
  }

 private:
  std::string NameOf(int64_t image_id) const {
    const auto it = image_index_.find(image_id);
    return it == image_index_.end() ? std::string("?") : out_->images.images[it->second].name;
  }

  int ImageIndex(int64_t image_id, const std::string& where) const {
    const auto it = image_index_.find(image_id);
    if (it == image_index_.end()) ThrowInput(path_, 0, where + ": no such image");
    return it->second;
  }

  // The pair of a pair id; `swapped` when name order runs against COLMAP's id order.
  PairMatches& Resolve(int64_t pair_id, const std::string& table, bool* swapped,
                       std::string* where) {
    uint32_t id1 = 0, id2 = 0;
    ColmapImageIdsFromPairId(static_cast<uint64_t>(pair_id), &id1, &id2);
    *where = "table " + table + ", pair_id " + std::to_string(pair_id) + " (image ids " +
             std::to_string(id1) + ", " + std::to_string(id2) + ")";
    const auto i1 = image_index_.find(id1), i2 = image_index_.find(id2);
    if (pair_id < 0 || i1 == image_index_.end() || i2 == image_index_.end() || id1 == id2) {
      ThrowInput(path_, 0, *where + ": no such image pair");
    }
    *where += " " + PairName(NameOf(id1), NameOf(id2));
    *swapped = i1->second > i2->second;
    const int a = std::min(i1->second, i2->second), b = std::max(i1->second, i2->second);
    PairMatches& pair = pairs_[{a, b}];
    pair.image1 = a;
    pair.image2 = b;
    return pair;
  }

  // Match rows index keypoints of COLMAP's image_id1 (left) and image_id2 (right).
  MatchMatrix CheckAndOrient(MatchMatrix m, const PairMatches& pair, bool swapped,
                             const std::string& where) const {
    // Columns of an empty matrix would be offsets from its null data pointer (undefined).
    if (swapped && m.rows() > 0) m.col(0).swap(m.col(1));
    const Eigen::Index n1 = out_->features[pair.image1].keypoints.rows();
    const Eigen::Index n2 = out_->features[pair.image2].keypoints.rows();
    for (Eigen::Index r = 0; r < m.rows(); ++r) {
      if (int64_t(m(r, 0)) >= n1 || int64_t(m(r, 1)) >= n2) {
        ThrowInput(path_, 0,
                   where + ": match " + std::to_string(r) + " (" + std::to_string(m(r, 0)) + ", " +
                       std::to_string(m(r, 1)) + ") is out of range for " + std::to_string(n1) +
                       " and " + std::to_string(n2) + " keypoints");
      }
    }
    return m;
  }

  // config, F, E, H and the relative pose of a two_view_geometries row, in raytime's pixel
  // convention and name order.
  void ReadGeometry(const Statement& stmt, bool swapped, const std::string& where,
                    TwoViewGeometry* g) const {
    const int64_t config = stmt.Int(4);
    if (config < 0 || config > static_cast<int>(TwoViewConfig::kMultiple)) {
      ThrowInput(path_, 0, where + ": unknown config " + std::to_string(config));
    }
    g->config = static_cast<TwoViewConfig>(config);
    Eigen::Matrix3d f = ReadMatrix3Blob(db_, stmt, 5, where + ", F");
    Eigen::Matrix3d e = ReadMatrix3Blob(db_, stmt, 6, where + ", E");
    Eigen::Matrix3d h = ReadMatrix3Blob(db_, stmt, 7, where + ", H");
    const Eigen::Vector4d qvec = ReadVectorBlob<4>(db_, stmt, 8, where + ", qvec");  // w x y z
    const Eigen::Vector3d tvec = ReadVectorBlob<3>(db_, stmt, 9, where + ", tvec");
    // COLMAP writes a zero quaternion when it did not estimate the relative pose.
    Rigid3 cam2_from_cam1;
    if (qvec.norm() > 0) {
      cam2_from_cam1 = Rigid3(Eigen::Quaterniond(qvec[0], qvec[1], qvec[2], qvec[3]), tvec);
    }
    if (swapped) {
      f.transposeInPlace();
      e.transposeInPlace();
      if (h != Eigen::Matrix3d::Zero()) h = h.inverse().eval();
      cam2_from_cam1 = cam2_from_cam1.Inverse();
    }
    g->F = ConvertF(f, ColmapFromOpenCvPixel());
    g->E = e;
    g->H = ConvertH(h, OpenCvFromColmapPixel(), ColmapFromOpenCvPixel());
    g->cam2_from_cam1 = cam2_from_cam1;
  }

  const Sqlite& db_;
  const std::string& path_;
  const std::map<int64_t, int>& image_index_;
  ColmapDatabase* out_;
  std::map<std::pair<int, int>, PairMatches> pairs_;
};

}  // namespace

ColmapDatabase ReadColmapDatabase(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "no such file (COLMAP database.db expected)");
  const Sqlite db(path, SQLITE_OPEN_READONLY);
  CheckTables(db);
  const std::map<int64_t, ColmapCamera> cameras = ReadDatabaseCameras(db, path);
  ColmapDatabase out;
  std::map<int64_t, int> image_index;
  ReadDatabaseImages(db, path, cameras, &out, &image_index);
  DatabaseTablesReader tables(db, path, image_index, &out);
  tables.ReadKeypoints();
  tables.ReadDescriptors();
  tables.ReadMatches();
  tables.ReadTwoViewGeometries();
  out.pairs = tables.TakePairs();
  return out;
}

namespace {

// What COLMAP would CHECK-fail (abort) on or misread, refused with the image or pair named:
// features per image, names sorted and unique, camera indices, descriptors per keypoint,
// non-negative scales, pair indices ascending and in range, matches within the keypoints.
void CheckDatabaseInput(const std::string& context, const ImageSet& images,
                        const std::vector<ImageFeatures>& features,
                        const std::vector<PairMatches>& pairs) {
  const size_t n = images.images.size();
  if (features.size() != n) {
    throw InputError(context + std::to_string(features.size()) + " feature sets for " +
                     std::to_string(n) + " images");
  }
  if (n >= kColmapMaxNumImages) throw InputError(context + "too many images");
  for (size_t i = 0; i < n; ++i) {
    const ImageInfo& info = images.images[i];
    if (i > 0 && !(images.images[i - 1].name < info.name)) {
      throw InputError(context + "images are not sorted by unique name (" +
                       images.images[i - 1].name + ", " + info.name + ")");
    }
    if (info.camera_index < 0 || size_t(info.camera_index) >= images.cameras.size()) {
      throw InputError(context + "image " + info.name + " has camera index " +
                       std::to_string(info.camera_index) + " out of range");
    }
    const ImageFeatures& f = features[i];
    if (f.descriptors.rows() != 0 && f.descriptors.rows() != f.keypoints.rows()) {
      throw InputError(context + "image " + info.name + " has " +
                       std::to_string(f.keypoints.rows()) + " keypoints and " +
                       std::to_string(f.descriptors.rows()) + " descriptors");
    }
    if (f.keypoints.rows() > 0 && (f.keypoints.col(2).array() < 0).any()) {
      // COLMAP CHECK-fails (aborts) on a negative keypoint scale.
      throw InputError(context + "image " + info.name + " has a keypoint with negative scale");
    }
  }
  for (const PairMatches& pair : pairs) {
    const std::string where =
        "pair " + std::to_string(pair.image1) + "_" + std::to_string(pair.image2);
    if (pair.image1 < 0 || pair.image2 < 0 || size_t(pair.image2) >= n ||
        pair.image1 >= pair.image2) {
      throw InputError(context + where + ": image indices out of range or not ascending");
    }
    const Eigen::Index n1 = features[pair.image1].keypoints.rows();
    const Eigen::Index n2 = features[pair.image2].keypoints.rows();
    for (const auto* m : {&pair.matches, &pair.geometry.inlier_matches}) {
      if (m->rows() > 0 &&
          (int64_t(m->col(0).maxCoeff()) >= n1 || int64_t(m->col(1).maxCoeff()) >= n2)) {
        throw InputError(
            context + where + " (" +
            PairName(images.images[pair.image1].name, images.images[pair.image2].name) +
            "): a match refers to a keypoint beyond " + std::to_string(n1) + " / " +
            std::to_string(n2));
      }
    }
  }
}

void InsertCameras(const Sqlite& db, const std::vector<ColmapCamera>& cameras) {
  Statement stmt(db,
                 "INSERT INTO cameras (camera_id, model, width, height, params, "
                 "prior_focal_length) VALUES (?, ?, ?, ?, ?, ?)");
  for (const ColmapCamera& camera : cameras) {
    stmt.BindInt(1, camera.camera_id);
    stmt.BindInt(2, ColmapModelId(camera.model));
    stmt.BindInt(3, static_cast<int64_t>(camera.width));
    stmt.BindInt(4, static_cast<int64_t>(camera.height));
    stmt.BindBlob(5, camera.params.data(), camera.params.size() * sizeof(double));
    // The focal length is calibrated, not guessed from EXIF: the mapper may trust it.
    stmt.BindInt(6, 1);
    stmt.Step("cannot write table cameras");
    stmt.Reset();
  }
}

// Images, keypoints (COLMAP's pixel convention: +0.5) and descriptors; image ids are 1 + index.
void InsertImagesAndFeatures(const Sqlite& db, const ImageSet& images,
                             const std::vector<ImageFeatures>& features) {
  Statement image_stmt(db, "INSERT INTO images (image_id, name, camera_id) VALUES (?, ?, ?)");
  Statement keypoint_stmt(db,
                          "INSERT INTO keypoints (image_id, rows, cols, data) VALUES (?, ?, ?, ?)");
  Statement descriptor_stmt(
      db, "INSERT INTO descriptors (image_id, rows, cols, data) VALUES (?, ?, ?, ?)");
  for (size_t i = 0; i < images.images.size(); ++i) {
    const int64_t image_id = static_cast<int64_t>(i + 1);
    image_stmt.BindInt(1, image_id);
    image_stmt.BindText(2, images.images[i].name);
    image_stmt.BindInt(3, images.images[i].camera_index + 1);
    image_stmt.Step("cannot write table images");
    image_stmt.Reset();

    const ImageFeatures& f = features[i];
    Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor> keypoints = f.keypoints;
    for (Eigen::Index r = 0; r < keypoints.rows(); ++r) {
      keypoints(r, 0) = static_cast<float>(double(f.keypoints(r, 0)) + 0.5);
      keypoints(r, 1) = static_cast<float>(double(f.keypoints(r, 1)) + 0.5);
    }
    keypoint_stmt.BindInt(1, image_id);
    keypoint_stmt.BindInt(2, keypoints.rows());
    keypoint_stmt.BindInt(3, 4);
    keypoint_stmt.BindBlob(4, keypoints.data(), keypoints.size() * sizeof(float));
    keypoint_stmt.Step("cannot write table keypoints");
    keypoint_stmt.Reset();

    descriptor_stmt.BindInt(1, image_id);
    descriptor_stmt.BindInt(2, f.descriptors.rows());
    descriptor_stmt.BindInt(3, f.descriptors.cols());
    descriptor_stmt.BindBlob(4, f.descriptors.data(), f.descriptors.size());
    descriptor_stmt.Step("cannot write table descriptors");
    descriptor_stmt.Reset();
  }
}

// Raw matches and two-view geometries (F and H in COLMAP's pixel convention).
void InsertPairs(const Sqlite& db, const std::vector<PairMatches>& pairs) {
  Statement match_stmt(db, "INSERT INTO matches (pair_id, rows, cols, data) VALUES (?, ?, ?, ?)");
  Statement geometry_stmt(db,
                          "INSERT INTO two_view_geometries (pair_id, rows, cols, data, "
                          "config, F, E, H, qvec, tvec) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, "
                          "?)");
  for (const PairMatches& pair : pairs) {
    // Image ids ascend with the indices, so COLMAP's (id1 < id2) orientation is ours.
    const auto pair_id = static_cast<int64_t>(ColmapPairId(static_cast<uint32_t>(pair.image1 + 1),
                                                           static_cast<uint32_t>(pair.image2 + 1)));
    match_stmt.BindInt(1, pair_id);
    match_stmt.BindInt(2, pair.matches.rows());
    match_stmt.BindInt(3, 2);
    match_stmt.BindBlob(4, pair.matches.data(), pair.matches.size() * sizeof(uint32_t));
    match_stmt.Step("cannot write table matches");
    match_stmt.Reset();

    const TwoViewGeometry& g = pair.geometry;
    using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    const RowMajor3 f = ConvertF(g.F, OpenCvFromColmapPixel());
    const RowMajor3 e = g.E;
    const RowMajor3 h = ConvertH(g.H, ColmapFromOpenCvPixel(), OpenCvFromColmapPixel());
    const Eigen::Quaterniond& q = g.cam2_from_cam1.rotation;
    const double qvec[4] = {q.w(), q.x(), q.y(), q.z()};
    const Eigen::Vector3d& tvec = g.cam2_from_cam1.translation;
    geometry_stmt.BindInt(1, pair_id);
    geometry_stmt.BindInt(2, g.inlier_matches.rows());
    geometry_stmt.BindInt(3, 2);
    geometry_stmt.BindBlob(4, g.inlier_matches.data(), g.inlier_matches.size() * sizeof(uint32_t));
    geometry_stmt.BindInt(5, static_cast<int>(g.config));
    geometry_stmt.BindBlob(6, f.data(), sizeof(double) * 9);
    geometry_stmt.BindBlob(7, e.data(), sizeof(double) * 9);
    geometry_stmt.BindBlob(8, h.data(), sizeof(double) * 9);
    geometry_stmt.BindBlob(9, qvec, sizeof(qvec));
    geometry_stmt.BindBlob(10, tvec.data(), sizeof(double) * 3);
    geometry_stmt.Step("cannot write table two_view_geometries");
    geometry_stmt.Reset();
  }
}

}  // namespace

void WriteColmapDatabase(const std::string& path, const ImageSet& images,
                         const std::vector<ImageFeatures>& features,
                         const std::vector<PairMatches>& pairs, const std::string& camera_model) {
  CheckDatabaseInput("cannot export the COLMAP database " + path + ": ", images, features, pairs);
  std::vector<ColmapCamera> cameras;
  for (size_t c = 0; c < images.cameras.size(); ++c) {
    cameras.push_back(
        ColmapCameraWithModel(images.cameras[c], static_cast<uint32_t>(c + 1), camera_model));
  }
  WriteAtomically(path, [&](const std::string& tmp) {
    // A leftover temporary database from a crashed run would be opened and appended to.
    std::error_code ignored;
    fs::remove(tmp, ignored);
    fs::remove(tmp + "-journal", ignored);
    const Sqlite db(tmp, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
    for (const char* sql : kSchema) db.Exec(sql, "cannot create COLMAP's tables");
    db.Exec("BEGIN TRANSACTION;", "cannot begin a transaction");
    InsertCameras(db, cameras);
    InsertImagesAndFeatures(db, images, features);
    InsertPairs(db, pairs);
    db.Exec("COMMIT;", "cannot commit the database");
  });
}

}  // namespace raytime

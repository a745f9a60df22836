#include "core/hdf5_store.h"

#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>

#include "core/error.h"
#include "core/version.h"
#include "testing/random_draws.h"
#include "tests/temp_dir_test.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

class Hdf5StoreTest : public TempDirTest {
 protected:
  Hdf5StoreTest() : TempDirTest("hdf5") {}

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::vector<std::string> DirectoryEntries() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_)) {
      names.push_back(entry.path().filename().string());
    }
    std::sort(names.begin(), names.end());
    return names;
  }
};

// The message of the InputError that `f` throws ("" when it throws none).
template <typename F>
std::string InputErrorMessage(F f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// Provenance with only the stage set; the writer fills the time and version.
Provenance StageOnly(const std::string& stage) {
  Provenance provenance;
  provenance.stage = stage;
  return provenance;
}

ImageSet SampleImages() {
  ImageSet images;
  images.image_root = "/data/scène/images";
  CameraIntrinsics a;
  a.width = 1536;
  a.height = 1024;
  a.params = {1382.1, 1381.9, 767.3, 511.7, -0.1, 0.01, 1e-4, -3e-5};
  CameraIntrinsics b;
  b.width = 640;
  b.height = 480;
  b.params = {500.0 / 3.0, 501, 319.5, 239.5, 0, 0, 0, 0};
  images.cameras = {a, b};
  images.images = {
      {"0000.jpg", 1536, 1024, 0}, {"0001.jpg", 1536, 1024, 0}, {"sub/ü-2.png", 640, 480, 1}};
  return images;
}

// Poses with non-representable decimals, so exact equality tests the float64 path.
PoseSet SamplePoses(unsigned seed, int count) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  PoseSet poses;
  for (int i = 0; i < count; ++i) {
    const Eigen::Quaterniond q = DrawQuaternion([&] { return normal(rng); }).normalized();
    poses.world_from_cam["000" + std::to_string(i) + ".jpg"] =
        Rigid3(q, DrawVector3([&] { return normal(rng); }) * 10.0);
  }
  return poses;
}

void ExpectSamePoses(const PoseSet& expected, const PoseSet& actual) {
  ASSERT_EQ(expected.size(), actual.size());
  for (const auto& [name, pose] : expected.world_from_cam) {
    ASSERT_TRUE(actual.Has(name)) << name;
    const Rigid3& other = actual.world_from_cam.at(name);
    EXPECT_EQ(pose.rotation.coeffs(), other.rotation.coeffs()) << name;
    EXPECT_EQ(pose.translation, other.translation) << name;
  }
}

std::vector<ImageFeatures> SampleFeatures() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coordinate(0, 1000);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<ImageFeatures> features(3);
  const int counts[] = {5, 0, 2};
  for (int i = 0; i < 3; ++i) {
    features[i].keypoints.resize(counts[i], 4);
    features[i].descriptors.resize(counts[i], 128);
    for (int k = 0; k < counts[i]; ++k) {
      features[i].keypoints.row(k) << coordinate(rng), coordinate(rng), 1.5f, -0.25f;
      for (int d = 0; d < 128; ++d) features[i].descriptors(k, d) = byte(rng);
    }
  }
  return features;
}

std::vector<PairMatches> SampleMatches() {
  PairMatches full;
  full.image1 = 0;
  full.image2 = 2;
  full.matches.resize(3, 2);
  full.matches << 0, 1, 2, 0, 4, 1;
  full.geometry.config = TwoViewConfig::kCalibrated;
  full.geometry.inlier_matches.resize(2, 2);
  full.geometry.inlier_matches << 0, 1, 4, 1;
  // Asymmetric matrices catch a transposed storage order.
  full.geometry.E << 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9;
  full.geometry.F = full.geometry.E * 1e-3;
  full.geometry.H << 1, 2, 3, 4, 5, 6, 7, 8, 1.0 / 3.0;
  full.geometry.cam2_from_cam1 =
      Rigid3(Eigen::Quaterniond(0.5, 0.5, -0.5, 0.5), Eigen::Vector3d(0.1, -0.2, 1.0 / 7.0));
  PairMatches empty;  // a pair with no matches at all must survive the round trip
  empty.image1 = 0;
  empty.image2 = 1;
  empty.geometry.config = TwoViewConfig::kDegenerate;
  return {full, empty};
}

void WriteSample(const std::string& path) {
  Hdf5Writer writer(path);
  writer.WriteImages(SampleImages());
  writer.WritePoseSet("ground_truth", SamplePoses(1, 3), PoseRole::kGroundTruth,
                      Provenance{"import", {{"format", "strecha"}}, "", ""});
  writer.Commit();
}

TEST_F(Hdf5StoreTest, RoundTripsEveryGroup) {
  const std::string path = Path("scene.h5");
  const ImageSet images = SampleImages();
  const PoseSet gt = SamplePoses(1, 3), prior = SamplePoses(2, 3), refined = SamplePoses(3, 2);
  const Provenance prior_provenance{"prior",
                                    {{"level_deg", 4.0}, {"mode", "iid"}, {"seed", 12}},
                                    "2024-05-01T10:00:00Z",
                                    "0.0.1-test"};
  const std::vector<ImageFeatures> features = SampleFeatures();
  const std::vector<PairMatches> matches = SampleMatches();
  const nlohmann::json summary = {{"cost", {1.5, 0.25}}, {"converged", true}, {"name", "ü"}};
  {
    Hdf5Writer writer(path);
    writer.WriteImages(images);
    writer.WritePoseSet("ground_truth", gt, PoseRole::kGroundTruth, StageOnly("import"));
    writer.WritePoseSet("prior", prior, PoseRole::kPrior, prior_provenance);
    writer.WritePoseSet("refined", refined, PoseRole::kRefined, StageOnly("refine"));
    writer.WriteFeatures(features, Provenance{"features", {{"sift", {{"peak", 0.0067}}}}, "", ""});
    writer.WriteMatches(matches, StageOnly("matches"));
    writer.WriteJson("summary", summary);
    writer.Commit();
  }

  Hdf5Reader reader(path);
  EXPECT_EQ(reader.path(), path);
  EXPECT_EQ(reader.schema_version(), kHdf5SchemaVersion);

  ASSERT_TRUE(reader.HasImages());
  const ImageSet read_images = reader.ReadImages();
  EXPECT_EQ(read_images.image_root, images.image_root);
  ASSERT_EQ(read_images.cameras.size(), 2u);
  EXPECT_TRUE(read_images.cameras[0] == images.cameras[0]);
  EXPECT_TRUE(read_images.cameras[1] == images.cameras[1]);
  ASSERT_EQ(read_images.images.size(), images.images.size());
  for (size_t i = 0; i < images.images.size(); ++i) {
    EXPECT_EQ(read_images.images[i].name, images.images[i].name);
    EXPECT_EQ(read_images.images[i].width, images.images[i].width);
    EXPECT_EQ(read_images.images[i].height, images.images[i].height);
    EXPECT_EQ(read_images.images[i].camera_index, images.images[i].camera_index);
  }

  EXPECT_EQ(reader.PoseSetNames(), (std::vector<std::string>{"ground_truth", "prior", "refined"}));
  EXPECT_TRUE(reader.HasPoseSet("prior"));
  EXPECT_FALSE(reader.HasPoseSet("other"));
  PoseRole role = PoseRole::kGroundTruth;
  Provenance provenance;
  ExpectSamePoses(prior, reader.ReadPoseSet("prior", &role, &provenance));
  EXPECT_EQ(role, PoseRole::kPrior);
  EXPECT_EQ(provenance.stage, "prior");
  EXPECT_EQ(provenance.options, prior_provenance.options);
  EXPECT_EQ(provenance.created_utc, "2024-05-01T10:00:00Z");
  EXPECT_EQ(provenance.raytime_version, "0.0.1-test");
  ExpectSamePoses(gt, reader.ReadPoseSet("ground_truth", &role));
  EXPECT_EQ(role, PoseRole::kGroundTruth);
  ExpectSamePoses(refined, reader.ReadPoseSet("refined", &role, &provenance));
  EXPECT_EQ(role, PoseRole::kRefined);
  // Empty provenance fields are filled by the writer.
  EXPECT_EQ(provenance.raytime_version, Version());
  EXPECT_EQ(provenance.created_utc.size(), std::string("2024-05-01T10:00:00Z").size());
  EXPECT_EQ(provenance.created_utc.back(), 'Z');
  EXPECT_TRUE(provenance.options.is_null());

  ASSERT_TRUE(reader.HasFeatures());
  const std::vector<ImageFeatures> read_features = reader.ReadFeatures(&provenance);
  EXPECT_EQ(provenance.stage, "features");
  EXPECT_EQ(provenance.options["sift"]["peak"], 0.0067);
  ASSERT_EQ(read_features.size(), features.size());
  for (size_t i = 0; i < features.size(); ++i) {
    EXPECT_EQ(read_features[i].keypoints, features[i].keypoints) << i;
    EXPECT_EQ(read_features[i].descriptors.rows(), features[i].descriptors.rows()) << i;
    EXPECT_EQ(read_features[i].descriptors.cols(), 128) << i;
    EXPECT_TRUE(read_features[i].descriptors == features[i].descriptors) << i;
  }

  ASSERT_TRUE(reader.HasMatches());
  const std::vector<PairMatches> read_matches = reader.ReadMatches(&provenance);
  EXPECT_EQ(provenance.stage, "matches");
  ASSERT_EQ(read_matches.size(), 2u);
  // Sorted by pair, whatever the write order.
  EXPECT_EQ(read_matches[0].image1, 0);
  EXPECT_EQ(read_matches[0].image2, 1);
  EXPECT_EQ(read_matches[0].matches.rows(), 0);
  EXPECT_EQ(read_matches[0].geometry.inlier_matches.rows(), 0);
  EXPECT_EQ(read_matches[0].geometry.config, TwoViewConfig::kDegenerate);
  const PairMatches& full = read_matches[1];
  const PairMatches& expected = matches[0];
  EXPECT_EQ(full.image1, 0);
  EXPECT_EQ(full.image2, 2);
  EXPECT_EQ(full.matches, expected.matches);
  EXPECT_EQ(full.geometry.inlier_matches, expected.geometry.inlier_matches);
  EXPECT_EQ(full.geometry.config, TwoViewConfig::kCalibrated);
  EXPECT_EQ(full.geometry.E, expected.geometry.E);
  EXPECT_EQ(full.geometry.F, expected.geometry.F);
  EXPECT_EQ(full.geometry.H, expected.geometry.H);
  EXPECT_EQ(full.geometry.cam2_from_cam1.rotation.coeffs(),
            expected.geometry.cam2_from_cam1.rotation.coeffs());
  EXPECT_EQ(full.geometry.cam2_from_cam1.translation, expected.geometry.cam2_from_cam1.translation);

  EXPECT_TRUE(reader.HasJson("summary"));
  EXPECT_FALSE(reader.HasJson("metrics"));
  EXPECT_EQ(reader.ReadJson("summary"), summary);
}

TEST_F(Hdf5StoreTest, AbsentGroupsAreNamedInErrors) {
  const std::string path = Path("gt_only.h5");
  WriteSample(path);
  Hdf5Reader reader(path);
  EXPECT_FALSE(reader.HasFeatures());
  EXPECT_FALSE(reader.HasMatches());
  const std::string pose_error = InputErrorMessage([&] { reader.ReadPoseSet("prior"); });
  EXPECT_NE(pose_error.find("file " + path + " has no pose set 'prior' (it has: ground_truth)"),
            std::string::npos)
      << pose_error;
  const std::string features_error = InputErrorMessage([&] { reader.ReadFeatures(); });
  EXPECT_NE(features_error.find(path), std::string::npos) << features_error;
  EXPECT_NE(features_error.find("features"), std::string::npos) << features_error;
  const std::string json_error = InputErrorMessage([&] { reader.ReadJson("summary"); });
  EXPECT_NE(json_error.find("'summary'"), std::string::npos) << json_error;
}

TEST_F(Hdf5StoreTest, EmptyFileHasNothing) {
  const std::string path = Path("empty.h5");
  {
    Hdf5Writer writer(path);
    writer.WritePoseSet("prior", PoseSet(), PoseRole::kPrior, StageOnly("prior"));
    writer.WriteMatches({}, StageOnly("matches"));
    writer.WriteFeatures({}, StageOnly("features"));
    writer.Commit();
  }
  Hdf5Reader reader(path);
  EXPECT_FALSE(reader.HasImages());
  EXPECT_EQ(reader.ReadPoseSet("prior").size(), 0u);
  EXPECT_TRUE(reader.ReadMatches().empty());
  EXPECT_TRUE(reader.ReadFeatures().empty());
  const std::string error = InputErrorMessage([&] { reader.ReadImages(); });
  EXPECT_NE(error.find("has no"), std::string::npos) << error;
}

TEST_F(Hdf5StoreTest, TruncatedFileIsAnInputError) {
  const std::string good = Path("good.h5"), truncated = Path("truncated.h5");
  WriteSample(good);
  std::ifstream in(good, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const std::string error = InputErrorMessage([&] { Hdf5Reader reader(truncated); });
  EXPECT_NE(error.find(truncated), std::string::npos) << error;
  EXPECT_NE(error.find("is not a readable HDF5 file (truncated or corrupt?)"), std::string::npos)
      << error;
}

TEST_F(Hdf5StoreTest, TextFileIsAnInputError) {
  const std::string path = Path("poses.txt");
  std::ofstream(path) << "0000.jpg 1 0 0 0 0 0 0\n";
  const std::string error = InputErrorMessage([&] { Hdf5Reader reader(path); });
  EXPECT_NE(error.find(path + ": is not a readable HDF5 file"), std::string::npos) << error;
}

TEST_F(Hdf5StoreTest, MissingFileIsAnInputError) {
  const std::string path = Path("absent.h5");
  const std::string error = InputErrorMessage([&] { Hdf5Reader reader(path); });
  EXPECT_NE(error.find(path + ": cannot open"), std::string::npos) << error;
}

// Rewrites a root attribute of a committed file in place with the raw C API.
void SetRootAttribute(const std::string& path, const char* name, hid_t type, const void* value) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  ASSERT_GE(H5Adelete(file, name), 0);
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attr = H5Acreate2(file, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(attr, 0);
  EXPECT_GE(H5Awrite(attr, type, value), 0);
  H5Aclose(attr);
  H5Sclose(space);
  H5Fclose(file);
}

TEST_F(Hdf5StoreTest, NewerSchemaVersionIsRejected) {
  const std::string path = Path("future.h5");
  WriteSample(path);
  const int version = kHdf5SchemaVersion + 1;
  SetRootAttribute(path, "schema_version", H5T_NATIVE_INT, &version);
  const std::string error = InputErrorMessage([&] { Hdf5Reader reader(path); });
  EXPECT_NE(error.find(path), std::string::npos) << error;
  EXPECT_NE(error.find("schema_version " + std::to_string(version)), std::string::npos) << error;
  EXPECT_NE(error.find("reads schema_version " + std::to_string(kHdf5SchemaVersion)),
            std::string::npos)
      << error;
}

TEST_F(Hdf5StoreTest, ForeignSchemaIsRejected) {
  const std::string path = Path("foreign.h5");
  WriteSample(path);
  // A fixed-length string, as other tools often write, must still be read and compared.
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, 8);
  const char value[8] = "colmap";
  SetRootAttribute(path, "schema", type, value);
  H5Tclose(type);
  const std::string error = InputErrorMessage([&] { Hdf5Reader reader(path); });
  EXPECT_NE(error.find(path), std::string::npos) << error;
  EXPECT_NE(error.find("\"colmap\", expected \"raytime\""), std::string::npos) << error;
}

TEST_F(Hdf5StoreTest, UncommittedWriterLeavesNothing) {
  {
    Hdf5Writer writer(Path("out.h5"));
    writer.WriteImages(SampleImages());
    EXPECT_EQ(DirectoryEntries().size(), 1u);  // only the temporary file exists meanwhile
    EXPECT_FALSE(fs::exists(Path("out.h5")));
  }
  EXPECT_TRUE(DirectoryEntries().empty());
}

TEST_F(Hdf5StoreTest, CommitReplacesExistingFile) {
  const std::string path = Path("out.h5");
  {
    Hdf5Writer writer(path);
    writer.WriteJson("run", {{"attempt", 1}});
    writer.Commit();
  }
  {
    Hdf5Writer writer(path);
    writer.WriteJson("run", {{"attempt", 2}});
    // Until Commit, readers still see the complete old file.
    EXPECT_EQ(Hdf5Reader(path).ReadJson("run")["attempt"], 1);
    writer.Commit();
    EXPECT_THROW(writer.WriteJson("late", 1), std::logic_error);
  }
  EXPECT_EQ(Hdf5Reader(path).ReadJson("run")["attempt"], 2);
  EXPECT_EQ(DirectoryEntries(), std::vector<std::string>{"out.h5"});
}

// /ray_times/<pose set> (the refine stage's solved observations, read by the 3DGS export):
// values round-trip bit-exactly, NaN included; inconsistent groups are refused on both sides.
TEST_F(Hdf5StoreTest, RayTimesRoundTripAndAreChecked) {
  RayTimeObservations rays;
  rays.image_names = {"0000.jpg", "0001.jpg"};
  rays.observations.resize(3, 2);
  rays.observations << 0, 5, 1, 7, 1, 9;
  rays.pixels.resize(3, 2);
  rays.pixels << 1.25, 2.5, 100.125, 200.0625, 3.0, 4.0;
  rays.ray_times.resize(3);
  rays.ray_times << 12.5, std::numeric_limits<double>::quiet_NaN(), 0.1;
  rays.matches.resize(2, 2);
  rays.matches << 0, 1, 0, 2;
  const std::string path = Path("refine.h5");
  {
    Hdf5Writer writer(path);
    writer.WriteRayTimes("refined@gnc", rays);
    writer.Commit();
  }
  {
    Hdf5Reader reader(path);
    EXPECT_TRUE(reader.HasRayTimes("refined@gnc"));
    EXPECT_FALSE(reader.HasRayTimes("refined"));
    const RayTimeObservations back = reader.ReadRayTimes("refined@gnc");
    EXPECT_EQ(back.image_names, rays.image_names);
    EXPECT_EQ(back.observations, rays.observations);
    EXPECT_EQ(back.pixels, rays.pixels);
    EXPECT_EQ(back.ray_times(0), 12.5);
    EXPECT_TRUE(std::isnan(back.ray_times(1)));
    EXPECT_EQ(back.ray_times(2), 0.1);
    EXPECT_EQ(back.matches, rays.matches);
    const std::string missing = InputErrorMessage([&] { reader.ReadRayTimes("refined"); });
    EXPECT_NE(missing.find("no ray times of pose set 'refined'"), std::string::npos) << missing;
  }

  RayTimeObservations bad = rays;
  bad.matches(1, 1) = 3;  // no observation 3
  EXPECT_THROW(Hdf5Writer(Path("bad.h5")).WriteRayTimes("refined", bad), std::invalid_argument);
  bad = rays;
  bad.observations(2, 0) = 2;  // no image row 2
  EXPECT_THROW(Hdf5Writer(Path("bad.h5")).WriteRayTimes("refined", bad), std::invalid_argument);
  bad = rays;
  bad.ray_times(0) = -1.0;  // the writer stores it; the reader refuses it
  {
    Hdf5Writer writer(path);
    writer.WriteRayTimes("refined", bad);
    writer.Commit();
  }
  const std::string negative = InputErrorMessage([&] { Hdf5Reader(path).ReadRayTimes("refined"); });
  EXPECT_NE(negative.find("observation 0 has ray time -1"), std::string::npos) << negative;
}

TEST_F(Hdf5StoreTest, WriterRejectsDuplicatesAndBadNames) {
  Hdf5Writer writer(Path("out.h5"));
  writer.WritePoseSet("prior", SamplePoses(1, 2), PoseRole::kPrior, StageOnly("prior"));
  EXPECT_THROW(
      writer.WritePoseSet("prior", SamplePoses(1, 2), PoseRole::kPrior, StageOnly("prior")),
      std::runtime_error);
  EXPECT_THROW(writer.WriteJson("a/b", 1), InputError);
  PairMatches backwards;
  backwards.image1 = 2;
  backwards.image2 = 1;
  EXPECT_THROW(writer.WriteMatches({backwards}, StageOnly("matches")), std::invalid_argument);
}

}  // namespace
}  // namespace raytime

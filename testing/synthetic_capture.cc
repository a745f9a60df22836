// A synthetic video-like capture of any length, written in raytime's HDF5 schema (issue 14), for
// the refiner's scaling benchmark (bench/refine_scaling.sh): cameras walk along a corridor at a
// fixed spacing (swaying ±10 cm), looking sideways at a wall of points 3–6 m away (the depths of a
// room capture);
// every point a camera sees is one keypoint (0.5 px noise by default), and every pair of frames at
// most --window apart is matched on the points both see, a --outliers fraction of each pair's
// matches replaced by a random keypoint of the second frame. With --laps L > 1 the frames walk
// the corridor L times (each lap on its own sway) and every pair of frames at most --window
// positions apart is matched whatever their laps: revisits, the loop closures whose fill-in of the
// reduced camera system a single pass does not have. The prior is the ground truth
// perturbed by the ladder protocol (evaluate/perturbation.h: i.i.d., --level degrees per frame,
// 1.25 % of the 4.5 m median depth per degree). Deterministic for a seed.
//
// For the fault-injection benchmark (issue 46, bench/fault_injection.py): --weak_link K leaves of
// the pairs across frame positions K-1 | K only (K-1, K), with --weak_link_matches of its matches
// (a corridor's doorway: the frames past it hang on the rest by one pair), and one fault of the
// image set may be injected: --focal_fault I:F (image I's camera given F times its focal length),
// --principal_fault I:DX:DY (its principal point moved), --swap I:J (the two images' content
// swapped: their keypoints and pairs change places, their names and priors do not), --foreign I
// (image I shows another scene: its pairs are two spurious ones of 25 random matches).
//
//   synthetic_capture --cameras N [--keypoints K] [--window W] [--laps L] [--noise PX]
//                     [--outliers F] [--level DEG] [--seed S] [--weak_link K]
//                     [--weak_link_matches M] [--focal_fault I:F | --principal_fault I:DX:DY |
//                     --swap I:J | --foreign I] --out DIR
//
// Writes DIR/dataset.h5 (images, cameras, ground_truth), DIR/features.h5 (keypoints, no
// descriptors), DIR/matches.h5 (verified inlier matches) and DIR/prior.h5 (pose set "prior"), so
// `raytime refine --in DIR/dataset.h5 DIR/features.h5 DIR/matches.h5 DIR/prior.h5` and `raytime
// evaluate` run on them; prints one JSON line (cameras, points, keypoints, pairs, matches).
#include <CLI/CLI.hpp>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/features.h"
#include "core/hdf5_store.h"
#include "core/types.h"
#include "evaluate/perturbation.h"

namespace raytime {
namespace {

struct CaptureOptions {
  int cameras = 100;
  int keypoints = 1000;  // points each frame sees, about
  int window = 10;       // frames matched ahead of each frame
  int laps = 1;          // passes along the corridor (revisits matched across passes)
  double noise_px = 0.5;
  double outliers = 0.05;
  double level_deg = 2.0;
  int seed = 0;
  int weak_link = 0;  // frame position; 0: none
  int weak_link_matches = 40;
  std::string focal_fault, principal_fault, swap, foreign;
  std::string out;
};

// Image 1280 x 960, f = 1000 px (a phone's main camera, 65° across).
constexpr int kWidth = 1280;
constexpr int kHeight = 960;
constexpr double kFocal = 1000.0;
constexpr double kNearDepth = 3.0;  // metres
constexpr double kFarDepth = 6.0;
constexpr double kWallHalfHeight = 1.5;
constexpr double kMedianDepth = 0.5 * (kNearDepth + kFarDepth);

// Numbers of a fault option "A:B:C".
std::vector<double> FaultNumbers(const std::string& value, size_t count, const char* option) {
  std::vector<double> numbers;
  std::stringstream in(value);
  std::string token;
  while (std::getline(in, token, ':')) numbers.push_back(std::stod(token));
  if (numbers.size() != count) {
    throw std::invalid_argument(std::string(option) + " '" + value + "': expected " +
                                std::to_string(count) + " numbers separated by ':'");
  }
  return numbers;
}

// Of the pairs across frame positions weak_link - 1 | weak_link only that pair, with at most
// weak_link_matches of its matches.
template <typename Position>
void KeepOnePairAcross(const CaptureOptions& o, const Position& position,
                       std::vector<PairMatches>* pairs) {
  std::vector<PairMatches> kept;
  for (PairMatches& pair : *pairs) {
    const int a = std::min(position(pair.image1), position(pair.image2));
    const int b = std::max(position(pair.image1), position(pair.image2));
    if (a < o.weak_link && b >= o.weak_link) {
      if (a != o.weak_link - 1 || b != o.weak_link) continue;
      const Eigen::Index n = std::min<Eigen::Index>(o.weak_link_matches, pair.matches.rows());
      pair.matches.conservativeResize(n, 2);
      pair.geometry.inlier_matches = pair.matches;
    }
    kept.push_back(std::move(pair));
  }
  *pairs = std::move(kept);
}

// Each verified pair's relative pose as the front end's essential matrix gives it (the prior
// convention check reads them): the true one, its baseline a unit direction.
void SetRelativePoses(const ImageSet& images, const PoseSet& ground_truth,
                      std::vector<PairMatches>* pairs) {
  for (PairMatches& pair : *pairs) {
    const Rigid3& a = ground_truth.world_from_cam.at(images.images[pair.image1].name);
    const Rigid3& b = ground_truth.world_from_cam.at(images.images[pair.image2].name);
    Rigid3 relative = b.Inverse() * a;
    relative.translation.normalize();
    pair.geometry.cam2_from_cam1 = relative;
  }
}

// The one fault of the image set the options ask for (the file's comment).
void InjectFault(const CaptureOptions& o, ImageSet* images, std::vector<ImageFeatures>* features,
                 std::vector<PairMatches>* pairs, std::mt19937_64* rng) {
  const int n = static_cast<int>(images->images.size());
  const auto frame = [&](double value) {
    const int i = static_cast<int>(value);
    if (i < 0 || i >= n) throw std::invalid_argument("fault frame out of range");
    return i;
  };
  const auto own_camera = [&](int i) {
    images->cameras.push_back(images->cameras[images->images[i].camera_index]);
    images->images[i].camera_index = static_cast<int>(images->cameras.size()) - 1;
    return &images->cameras.back();
  };
  if (!o.focal_fault.empty()) {
    const std::vector<double> f = FaultNumbers(o.focal_fault, 2, "--focal_fault");
    CameraIntrinsics* camera = own_camera(frame(f[0]));
    camera->params[kFx] *= f[1];
    camera->params[kFy] *= f[1];
  }
  if (!o.principal_fault.empty()) {
    const std::vector<double> p = FaultNumbers(o.principal_fault, 3, "--principal_fault");
    CameraIntrinsics* camera = own_camera(frame(p[0]));
    camera->params[kCx] += p[1];
    camera->params[kCy] += p[2];
  }
  if (!o.swap.empty()) {
    const std::vector<double> s = FaultNumbers(o.swap, 2, "--swap");
    const int i = frame(s[0]), j = frame(s[1]);
    std::swap((*features)[i], (*features)[j]);
    for (PairMatches& pair : *pairs) {
      for (int* image : {&pair.image1, &pair.image2}) {
        *image = *image == i ? j : *image == j ? i : *image;
      }
      if (pair.image1 > pair.image2) {
        std::swap(pair.image1, pair.image2);
        pair.matches.col(0).swap(pair.matches.col(1));
        pair.geometry.inlier_matches = pair.matches;
        pair.geometry.cam2_from_cam1 = pair.geometry.cam2_from_cam1.Inverse();
        pair.geometry.cam2_from_cam1.translation.normalize();
      }
    }
  }
  if (!o.foreign.empty()) {
    const int i = frame(FaultNumbers(o.foreign, 1, "--foreign")[0]);
    std::uniform_int_distribution<int> pick(0, n - 1);
    pairs->erase(
        std::remove_if(pairs->begin(), pairs->end(),
                       [&](const PairMatches& p) { return p.image1 == i || p.image2 == i; }),
        pairs->end());
    for (int k = 0; k < 2; ++k) {
      int other = pick(*rng);
      while (other == i) other = pick(*rng);
      PairMatches pair;
      pair.image1 = std::min(i, other);
      pair.image2 = std::max(i, other);
      pair.matches.resize(25, 2);
      for (Eigen::Index m = 0; m < 25; ++m) {
        for (const int c : {0, 1}) {
          const int image = c == 0 ? pair.image1 : pair.image2;
          std::uniform_int_distribution<int> keypoint(
              0, static_cast<int>((*features)[image].keypoints.rows()) - 1);
          pair.matches(m, c) = static_cast<uint32_t>(keypoint(*rng));
        }
      }
      pair.geometry.config = TwoViewConfig::kCalibrated;
      pair.geometry.inlier_matches = pair.matches;
      pairs->push_back(std::move(pair));
    }
  }
}

// The command line, onto `o`.
void AddOptions(CLI::App& app, CaptureOptions& o) {
  app.add_option("--cameras", o.cameras, "Frames")->check(CLI::PositiveNumber);
  app.add_option("--keypoints", o.keypoints, "Points each frame sees, about")
      ->check(CLI::PositiveNumber);
  app.add_option("--window", o.window, "Frames matched ahead of each frame")
      ->check(CLI::PositiveNumber);
  app.add_option("--laps", o.laps,
                 "Passes along the corridor; frames at most --window positions apart are matched "
                 "across passes (loop closures)")
      ->check(CLI::PositiveNumber);
  app.add_option("--noise", o.noise_px, "Keypoint noise, pixels (standard deviation)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--outliers", o.outliers, "Fraction of each pair's matches made wrong")
      ->check(CLI::Range(0.0, 0.99));
  app.add_option("--level", o.level_deg, "Prior perturbation, degrees per frame (i.i.d.)")
      ->check(CLI::Range(0.0, 180.0));
  app.add_option("--seed", o.seed, "Seed of the scene, noise, outliers and prior");
  app.add_option("--weak_link", o.weak_link,
                 "Frame position K: of the pairs across K-1 | K only (K-1, K) is kept; 0 = none")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--weak_link_matches", o.weak_link_matches,
                 "Matches the weak link's one pair keeps")
      ->check(CLI::PositiveNumber);
  auto* faults = app.add_option_group("fault", "One fault of the image set (issue 46)");
  faults->add_option("--focal_fault", o.focal_fault, "I:F: image I's focal length given F times");
  faults->add_option("--principal_fault", o.principal_fault,
                     "I:DX:DY: image I's principal point given DX, DY px off");
  faults->add_option("--swap", o.swap, "I:J: the two images' content swapped");
  faults->add_option("--foreign", o.foreign, "I: image I shows another scene");
  faults->require_option(0, 1);
  app.add_option("--out", o.out, "Output directory")->required();
}

// The corridor's layout. A frame's footprint on the wall at the median depth is kWidth / kFocal *
// depth wide; the spacing puts the last frame of the window half a footprint along, so neighbours
// share most points and the window's far end about half.
struct Corridor {
  explicit Corridor(const CaptureOptions& o)
      : spacing(footprint / (2.0 * o.window)),
        per_lap((o.cameras + o.laps - 1) / o.laps),
        length((per_lap - 1) * spacing + 2 * margin) {}

  int Position(int frame) const { return frame % per_lap; }

  const double footprint = kWidth / kFocal * kMedianDepth;
  const double height = std::min(2.0 * kWallHalfHeight, kHeight / kFocal * kMedianDepth);
  const double margin = footprint;
  const double spacing;
  const int per_lap;  // frame positions along the corridor
  const double length;
};

// The wall's points, sorted along the corridor, about `keypoints` in each frame's footprint.
std::vector<Eigen::Vector3d> WallPoints(const CaptureOptions& o, const Corridor& corridor,
                                        std::mt19937_64* rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double density = o.keypoints / (corridor.footprint * corridor.height);  // per m² of wall
  const int num_points = static_cast<int>(density * corridor.length * 2 * kWallHalfHeight);
  std::vector<Eigen::Vector3d> points(num_points);
  for (Eigen::Vector3d& p : points) {
    p = Eigen::Vector3d(-corridor.margin + corridor.length * unit(*rng),
                        kNearDepth + (kFarDepth - kNearDepth) * unit(*rng),
                        kWallHalfHeight * (2 * unit(*rng) - 1));
  }
  std::sort(points.begin(), points.end(),
            [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return a.x() < b.x(); });
  return points;
}

// The frames: images, true poses and noisy keypoints, with per frame the keypoint of each point it
// sees, by point index (sorted).
struct Frames {
  ImageSet images;
  PoseSet ground_truth;
  std::vector<ImageFeatures> features;
  std::vector<std::vector<std::pair<int, int>>> seen;
};

// Frame i's keypoints: the points in its footprint that land inside the image, with noise.
void Observe(int i, const Rigid3& pose, const std::vector<Eigen::Vector3d>& points,
             const Corridor& corridor, std::normal_distribution<double>* noise,
             std::mt19937_64* rng, Frames* frames) {
  const Rigid3 cam_from_world = pose.Inverse();
  const double x_min = pose.translation.x() - corridor.footprint;
  const auto first = std::lower_bound(points.begin(), points.end(), x_min,
                                      [](const Eigen::Vector3d& p, double x) { return p.x() < x; });
  std::vector<Eigen::Vector2d> pixels;
  for (auto it = first; it != points.end() && it->x() < pose.translation.x() + corridor.footprint;
       ++it) {
    const Eigen::Vector3d p = cam_from_world * *it;
    const Eigen::Vector2d u(kFocal * p.x() / p.z() + kWidth / 2.0,
                            kFocal * p.y() / p.z() + kHeight / 2.0);
    if (u.x() < 0 || u.x() >= kWidth || u.y() < 0 || u.y() >= kHeight) continue;
    frames->seen[i].emplace_back(static_cast<int>(it - points.begin()),
                                 static_cast<int>(pixels.size()));
    pixels.push_back(u + Eigen::Vector2d((*noise)(*rng), (*noise)(*rng)));
  }
  auto& keypoints = frames->features[i].keypoints;
  keypoints.resize(static_cast<Eigen::Index>(pixels.size()), 4);
  for (size_t k = 0; k < pixels.size(); ++k) {
    keypoints.row(static_cast<Eigen::Index>(k)) << static_cast<float>(pixels[k].x()),
        static_cast<float>(pixels[k].y()), 2.0f, 0.0f;
  }
}

Frames WalkCorridor(const CaptureOptions& o, const Corridor& corridor,
                    const std::vector<Eigen::Vector3d>& points, std::mt19937_64* rng) {
  std::normal_distribution<double> noise(0.0, o.noise_px);
  // Camera frame: x = world x, y = world -z (image down), z = world y (towards the wall).
  Eigen::Matrix3d world_from_cam_rotation;
  world_from_cam_rotation << 1, 0, 0, 0, 0, 1, 0, -1, 0;
  Frames frames;
  CameraIntrinsics camera;
  camera.params = {kFocal, kFocal, kWidth / 2.0, kHeight / 2.0, 0, 0, 0, 0};
  frames.images.cameras = {camera};
  frames.features.resize(o.cameras);
  frames.seen.resize(o.cameras);
  for (int i = 0; i < o.cameras; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    frames.images.images.push_back({name, kWidth, kHeight, 0});
    // A hand-held walk, not a rail: the centre sways ±10 cm in depth and height (collinear
    // centres would leave the roll about the corridor to the gauge and Sim(3) alignment undefined).
    // Each lap sways on its own phase, so revisits see the wall from other centres.
    const double phase = 1.7 * (i / corridor.per_lap);
    const Rigid3 pose(
        Eigen::Quaterniond(world_from_cam_rotation),
        Eigen::Vector3d(corridor.Position(i) * corridor.spacing, 0.1 * std::sin(0.13 * i + phase),
                        0.1 * std::sin(0.07 * i + phase)));
    frames.ground_truth.world_from_cam[name] = pose;
    Observe(i, pose, points, corridor, &noise, rng, &frames);
  }
  return frames;
}

// Every pair of frames at most `window` positions apart with at least 20 common points, matched on
// them, an `outliers` fraction of each pair's matches replaced by a random keypoint of the second.
std::vector<PairMatches> MatchFrames(const CaptureOptions& o, const Corridor& corridor,
                                     const Frames& frames, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<PairMatches> pairs;
  for (int i = 0; i < o.cameras; ++i) {
    for (int j = i + 1; j < o.cameras; ++j) {
      if (std::abs(corridor.Position(j) - corridor.Position(i)) > o.window) continue;
      const auto& seen_i = frames.seen[i];
      const auto& seen_j = frames.seen[j];
      std::vector<std::pair<uint32_t, uint32_t>> matches;
      auto a = seen_i.begin();
      auto b = seen_j.begin();
      while (a != seen_i.end() && b != seen_j.end()) {
        if (a->first < b->first) {
          ++a;
        } else if (b->first < a->first) {
          ++b;
        } else {
          matches.emplace_back((a++)->second, (b++)->second);
        }
      }
      if (matches.size() < 20) continue;
      const auto keypoints_j = static_cast<uint32_t>(seen_j.size());
      for (auto& m : matches) {
        if (unit(*rng) < o.outliers) m.second = static_cast<uint32_t>(unit(*rng) * keypoints_j);
      }
      PairMatches pair;
      pair.image1 = i;
      pair.image2 = j;
      pair.matches.resize(static_cast<Eigen::Index>(matches.size()), 2);
      for (size_t m = 0; m < matches.size(); ++m) {
        pair.matches.row(static_cast<Eigen::Index>(m)) << matches[m].first, matches[m].second;
      }
      pair.geometry.config = TwoViewConfig::kCalibrated;
      pair.geometry.inlier_matches = pair.matches;
      pairs.push_back(std::move(pair));
    }
  }
  return pairs;
}

// DIR/dataset.h5, features.h5, matches.h5 and prior.h5, with the options as provenance.
void WriteCapture(const CaptureOptions& o, const Frames& frames,
                  const std::vector<PairMatches>& pairs, const PoseSet& prior) {
  std::filesystem::create_directories(o.out);
  Provenance provenance;
  provenance.stage = "synthetic_capture";
  provenance.options = {{"cameras", o.cameras},
                        {"keypoints", o.keypoints},
                        {"window", o.window},
                        {"laps", o.laps},
                        {"noise_px", o.noise_px},
                        {"outliers", o.outliers},
                        {"level_deg", o.level_deg},
                        {"seed", o.seed},
                        {"weak_link", o.weak_link},
                        {"focal_fault", o.focal_fault},
                        {"principal_fault", o.principal_fault},
                        {"swap", o.swap},
                        {"foreign", o.foreign}};
  {
    Hdf5Writer writer(o.out + "/dataset.h5");
    writer.WriteImages(frames.images);
    writer.WritePoseSet("ground_truth", frames.ground_truth, PoseRole::kGroundTruth, provenance);
    writer.Commit();
  }
  {
    Hdf5Writer writer(o.out + "/features.h5");
    writer.WriteFeatures(frames.features, provenance);
    writer.Commit();
  }
  {
    Hdf5Writer writer(o.out + "/matches.h5");
    writer.WriteMatches(pairs, provenance);
    writer.Commit();
  }
  {
    Hdf5Writer writer(o.out + "/prior.h5");
    writer.WritePoseSet("prior", prior, PoseRole::kPrior, provenance);
    writer.Commit();
  }
}

int Main(int argc, char** argv) {
  CaptureOptions o;
  CLI::App app("Synthetic corridor capture in raytime's HDF5 schema (issue 14 scaling benchmark)");
  AddOptions(app, o);
  CLI11_PARSE(app, argc, argv);

  // 1. The wall, the walk along it and the matches (one generator: the scene, the noise and the
  // outliers in this order, then the fault).
  const Corridor corridor(o);
  std::mt19937_64 rng(o.seed);
  const std::vector<Eigen::Vector3d> points = WallPoints(o, corridor, &rng);
  Frames frames = WalkCorridor(o, corridor, points, &rng);
  std::vector<PairMatches> pairs = MatchFrames(o, corridor, frames, &rng);

  // 2. The weak link and the fault the options ask for.
  const auto position = [&](int i) { return corridor.Position(i); };
  if (o.weak_link > 0) KeepOnePairAcross(o, position, &pairs);
  SetRelativePoses(frames.images, frames.ground_truth, &pairs);
  InjectFault(o, &frames.images, &frames.features, &pairs, &rng);

  // 3. The prior: the ground truth perturbed by the ladder protocol.
  PerturbationOptions perturbation;
  perturbation.level_deg = o.level_deg;
  perturbation.translation_unit = "metres";
  perturbation.translation_per_deg = 0.0125 * kMedianDepth;
  perturbation.seed = o.seed;
  const PoseSet prior = PerturbPoses(frames.ground_truth, perturbation);

  // 4. The files and one JSON line.
  WriteCapture(o, frames, pairs, prior);
  long long num_keypoints = 0, num_matches = 0;
  for (const ImageFeatures& f : frames.features) num_keypoints += f.keypoints.rows();
  for (const PairMatches& pair : pairs) num_matches += pair.matches.rows();
  std::printf("%s\n", nlohmann::json({{"cameras", o.cameras},
                                      {"points", points.size()},
                                      {"keypoints", num_keypoints},
                                      {"pairs", pairs.size()},
                                      {"matches", num_matches},
                                      {"spacing_m", corridor.spacing}})
                          .dump()
                          .c_str());
  return 0;
}

}  // namespace
}  // namespace raytime

int main(int argc, char** argv) { return raytime::Main(argc, argv); }

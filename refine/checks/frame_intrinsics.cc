#include "refine/checks/frame_intrinsics.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/loss_function.h>
#include <ceres/manifold.h>
#include <ceres/problem.h>
#include <ceres/rotation.h>
#include <ceres/solver.h>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "core/statistics.h"

namespace raytime {
namespace {

// Matches sampled per pair: enough for a median, few enough for a small solve per frame.
constexpr int kRefitSamplesPerPair = 100;
// The robust loss's scale, pixels: matches a few pixels off (outliers, a wrong pair) stop pulling.
constexpr double kLossScalePx = 2.0;
constexpr int kMaxIterations = 50;
// The free fit's focal length stays within this factor of the given one.
constexpr double kMaxFocalFactor = 3.0;

// One match of the tested frame: its keypoint (as observed) and the other frame's ray and centre.
struct EpipolarSample {
  Eigen::Vector2d observed;
  Eigen::Vector3d other_ray;  // unit, world
  Eigen::Vector3d other_centre;
  int other = 0;  // the other frame (the pair)
};

// Each pair's fit: the median |residual| of its sampled matches, by the other frame. Judged per
// pair, so that a wrong pair (repeated structure matched to the wrong copy, castle-P19's walls)
// counts as one pair, not as its many matches.
using PairFits = std::map<int, double>;

PairFits FitsOfPairs(const std::vector<EpipolarSample>& samples,
                     const std::vector<double>& residuals) {
  std::map<int, std::vector<double>> by_pair;
  for (size_t k = 0; k < samples.size(); ++k) {
    by_pair[samples[k].other].push_back(std::abs(residuals[k]));
  }
  PairFits fits;
  for (auto& [other, values] : by_pair) fits[other] = Median(std::move(values), 0.0);
  return fits;
}

// The median over the pairs `judged` (all when empty) of their fits.
double MedianOf(const PairFits& fits, const std::set<int>& judged = {}) {
  std::vector<double> medians;
  for (const auto& [other, fit] : fits) {
    if (judged.empty() || judged.count(other)) medians.push_back(fit);
  }
  return Median(medians, 0.0);
}

// Adds the pairs that `fits` explains (within `explained_px`) to `judged`.
void AddExplained(const PairFits& fits, double explained_px, std::set<int>* judged) {
  for (const auto& [other, fit] : fits) {
    if (fit <= explained_px) judged->insert(other);
  }
}

// Distance, in the tested frame's pixels (its focal length times the sine), of its keypoint's ray
// from the epipolar plane spanned by the other frame's ray and the two centres. Parameters: the
// rotation update ω (R = R₀ Exp(ω), world from camera), the centre, and (log focal factor, Δcx,
// Δcy) on the given intrinsics.
struct EpipolarPlaneCost {
  EpipolarPlaneCost(const EpipolarSample& sample, const Eigen::Matrix3d& rotation0,
                    const CameraIntrinsics& given)
      : sample_(sample), rotation0_(rotation0), given_(given) {}

  template <typename T>
  bool operator()(const T* omega, const T* centre, const T* intrinsics, T* residual) const {
    using std::exp;
    using std::sqrt;
    const T factor = exp(intrinsics[0]);
    T k[kNumIntrinsics];
    for (int p = 0; p < kNumIntrinsics; ++p) k[p] = T(given_.params[p]);
    k[kFx] *= factor;
    k[kFy] *= factor;
    k[kCx] += intrinsics[1];
    k[kCy] += intrinsics[2];
    const T observed[2] = {T(sample_.observed.x()), T(sample_.observed.y())};
    T ray[3], turned[3];
    ObservedPixelToUnitRay(k, observed, ray);
    ceres::AngleAxisRotatePoint(omega, ray, turned);
    T direction[3];
    for (int r = 0; r < 3; ++r) {
      direction[r] = T(rotation0_(r, 0)) * turned[0] + T(rotation0_(r, 1)) * turned[1] +
                     T(rotation0_(r, 2)) * turned[2];
    }
    const T baseline[3] = {T(sample_.other_centre.x()) - centre[0],
                           T(sample_.other_centre.y()) - centre[1],
                           T(sample_.other_centre.z()) - centre[2]};
    const T w[3] = {T(sample_.other_ray.x()), T(sample_.other_ray.y()), T(sample_.other_ray.z())};
    const T normal[3] = {baseline[1] * w[2] - baseline[2] * w[1],
                         baseline[2] * w[0] - baseline[0] * w[2],
                         baseline[0] * w[1] - baseline[1] * w[0]};
    const T length =
        sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]) + T(1e-300);
    const T sine =
        (normal[0] * direction[0] + normal[1] * direction[1] + normal[2] * direction[2]) / length;
    // In the given focal length's pixels: measured in the candidate's, a focal shrunk towards 0
    // would shrink every residual with it.
    residual[0] = T(0.5 * (given_.params[kFx] + given_.params[kFy])) * sine;
    return true;
  }

  EpipolarSample sample_;
  Eigen::Matrix3d rotation0_;
  CameraIntrinsics given_;
};

// The frame's samples: up to kRefitSamplesPerPair evenly spaced matches of each of its pairs.
std::vector<EpipolarSample> SamplesOf(int image, const RefineInput& input,
                                      const std::vector<Rigid3>& world_from_cam,
                                      const std::vector<CameraIntrinsics>& intrinsics) {
  std::vector<EpipolarSample> samples;
  for (const PairMatchIndices& pair : input.pairs) {
    if (pair.image1 != image && pair.image2 != image) continue;
    const bool first = pair.image1 == image;
    const int other = first ? pair.image2 : pair.image1;
    const Eigen::Index n = pair.matches.rows();
    const Eigen::Index stride = std::max<Eigen::Index>(1, n / kRefitSamplesPerPair);
    const Eigen::Matrix3d other_rotation = world_from_cam[other].rotation.toRotationMatrix();
    for (Eigen::Index m = 0; m < n; m += stride) {
      const uint32_t own_keypoint = pair.matches(m, first ? 0 : 1);
      const uint32_t other_keypoint = pair.matches(m, first ? 1 : 0);
      EpipolarSample sample;
      sample.observed = input.keypoints[image].row(own_keypoint).transpose();
      const Eigen::Vector2d other_pixel = input.keypoints[other].row(other_keypoint).transpose();
      Eigen::Vector3d ray;
      ObservedPixelToUnitRay(intrinsics[other].params.data(), other_pixel.data(), ray.data());
      sample.other_ray = other_rotation * ray;
      sample.other_centre = world_from_cam[other].translation;
      sample.other = other;
      samples.push_back(sample);
    }
  }
  return samples;
}

// What a fit may move besides the pose.
enum class FreeIntrinsics { kNone, kFocal, kPrincipalPoint, kBoth };

// The pairs' fits after fitting the frame's pose (and the intrinsics `free` names) to `samples`
// from `start`; `intrinsics` receives (log focal factor, Δcx, Δcy). False when a free
// intrinsic ended at its bound: within a factor kMaxFocalFactor of the given focal length and half
// the image of its principal point, since beyond, a frame's rays collapse onto a line or spread
// over a hemisphere and what they "explain" is degenerate geometry, not a lens.
bool FitPairs(const std::vector<EpipolarSample>& samples, const Rigid3& start,
              const CameraIntrinsics& given, FreeIntrinsics free, double intrinsics[3],
              PairFits* fits) {
  double omega[3] = {0, 0, 0};
  double centre[3] = {start.translation.x(), start.translation.y(), start.translation.z()};
  intrinsics[0] = intrinsics[1] = intrinsics[2] = 0.0;
  const Eigen::Matrix3d rotation0 = start.rotation.toRotationMatrix();
  ceres::Problem problem;
  std::vector<ceres::CostFunction*> costs;
  for (const EpipolarSample& sample : samples) {
    auto* cost = new ceres::AutoDiffCostFunction<EpipolarPlaneCost, 1, 3, 3, 3>(
        new EpipolarPlaneCost(sample, rotation0, given));
    costs.push_back(cost);
    problem.AddResidualBlock(cost, new ceres::CauchyLoss(kLossScalePx), omega, centre, intrinsics);
  }
  const double bound[3] = {std::log(kMaxFocalFactor), 0.5 * given.width, 0.5 * given.height};
  std::vector<int> held;
  if (free == FreeIntrinsics::kNone || free == FreeIntrinsics::kPrincipalPoint) held.push_back(0);
  if (free == FreeIntrinsics::kNone || free == FreeIntrinsics::kFocal) {
    held.insert(held.end(), {1, 2});
  }
  if (held.size() == 3) {
    problem.SetParameterBlockConstant(intrinsics);
  } else {
    if (!held.empty()) {
      problem.SetManifold(intrinsics, new ceres::SubsetManifold(3, held));
    }
    for (int p = 0; p < 3; ++p) {
      problem.SetParameterLowerBound(intrinsics, p, -bound[p]);
      problem.SetParameterUpperBound(intrinsics, p, bound[p]);
    }
  }
  ceres::Solver::Options options;
  options.max_num_iterations = kMaxIterations;
  options.linear_solver_type = ceres::DENSE_QR;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  std::vector<double> values;
  const double* parameters[3] = {omega, centre, intrinsics};
  for (ceres::CostFunction* cost : costs) {
    double residual = 0.0;
    cost->Evaluate(parameters, &residual, nullptr);
    values.push_back(residual);
  }
  *fits = FitsOfPairs(samples, values);
  for (int p = 0; p < 3; ++p) {
    if (std::abs(intrinsics[p]) >= 0.95 * bound[p]) return false;
  }
  return true;
}

// The frame's test: its fit with the intrinsics as given, and the best of the fits that free the
// focal length, the principal point or both (a fit ending at a bound counts as none; both only
// when it beats the better single one by kBothMargin, since two groups trade against each other).
// All are judged on the same pairs: those explained (within `explained_px`) with the intrinsics as
// given or by one of the fits. A wrong pair neither explains stays out, else with half a frame's
// pairs wrong the median pair is the worst right one, and a fit that trades the others for it
// "explains" a correct frame (castle-P19's 0015, its principal point "off" 12 %); a frame whose
// wrong focal length made the pair removal take its pairs has them back in, explained by the fit.
constexpr double kBothMargin = 1.25;

void TestFrame(const std::vector<EpipolarSample>& samples, const Rigid3& start,
               const CameraIntrinsics& given, double explained_px, FrameIntrinsicsTest* test) {
  double held[3];
  PairFits given_fits;
  FitPairs(samples, start, given, FreeIntrinsics::kNone, held, &given_fits);
  struct Candidate {
    FreeIntrinsics free;
    double intrinsics[3];
    PairFits fits;
  };
  std::vector<Candidate> candidates;
  std::set<int> judged;
  AddExplained(given_fits, explained_px, &judged);
  for (const FreeIntrinsics free :
       {FreeIntrinsics::kFocal, FreeIntrinsics::kPrincipalPoint, FreeIntrinsics::kBoth}) {
    Candidate candidate{free, {0, 0, 0}, {}};
    if (!FitPairs(samples, start, given, free, candidate.intrinsics, &candidate.fits)) continue;
    AddExplained(candidate.fits, explained_px, &judged);
    candidates.push_back(std::move(candidate));
  }
  test->pairs_judged = static_cast<int>(judged.size());
  if (judged.empty()) return;  // nothing explained either way: nothing to compare
  test->given_median_px = test->free_median_px = MedianOf(given_fits, judged);
  double best[3] = {0, 0, 0};
  for (const Candidate& candidate : candidates) {
    const double median = MedianOf(candidate.fits, judged);
    const double needed = candidate.free == FreeIntrinsics::kBoth ? kBothMargin : 1.0;
    if (median * needed >= test->free_median_px) continue;
    test->free_median_px = median;
    std::copy(candidate.intrinsics, candidate.intrinsics + 3, best);
  }
  test->focal_factor = std::exp(best[0]);
  test->principal_shift_px = {best[1], best[2]};
}

// The median over its pairs of their fits at `pose` with the intrinsics as given, no fit.
double CurrentMedian(const std::vector<EpipolarSample>& samples, const Rigid3& pose,
                     const CameraIntrinsics& given) {
  const double omega[3] = {0, 0, 0}, no_change[3] = {0, 0, 0};
  const double centre[3] = {pose.translation.x(), pose.translation.y(), pose.translation.z()};
  const Eigen::Matrix3d rotation = pose.rotation.toRotationMatrix();
  std::vector<double> values;
  for (const EpipolarSample& sample : samples) {
    double residual = 0.0;
    EpipolarPlaneCost(sample, rotation, given)(omega, centre, no_change, &residual);
    values.push_back(residual);
  }
  return MedianOf(FitsOfPairs(samples, values));
}

}  // namespace

std::vector<FrameFinding> CheckFrameIntrinsics(const RefineInput& input,
                                               const std::vector<Rigid3>& world_from_cam,
                                               const std::vector<CameraIntrinsics>& intrinsics,
                                               double explained_pair_px, int num_threads,
                                               std::vector<FrameIntrinsicsTest>* tests) {
  const int n = static_cast<int>(world_from_cam.size());
  std::vector<FrameIntrinsicsTest> all(n);
  std::vector<std::vector<EpipolarSample>> samples(n);
  std::vector<bool> measured(n, false);
  tbb::task_arena arena(std::max(1, num_threads));
  // 1. Every frame's fit as it stands (no solve: cheap).
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 1), [&](const tbb::blocked_range<int>& range) {
      for (int image = range.begin(); image < range.end(); ++image) {
        samples[image] = SamplesOf(image, input, world_from_cam, intrinsics);
        if (static_cast<int>(samples[image].size()) < kMinIntrinsicsMatches) continue;
        all[image].image = image;
        all[image].num_matches = static_cast<int>(samples[image].size());
        all[image].given_median_px = all[image].free_median_px =
            CurrentMedian(samples[image], world_from_cam[image], intrinsics[image]);
        measured[image] = true;
      }
    });
  });
  std::vector<double> current;
  for (int image = 0; image < n; ++image) {
    if (measured[image]) current.push_back(all[image].given_median_px);
  }
  const double gate =
      std::max(kMinIntrinsicsGivenPx, kMinIntrinsicsGivenMultiple * Median(current, 0.0));
  // 2. Only the frames that fit worse than the others have anything for other intrinsics to
  // explain: their pose refitted with the intrinsics as given, then with them free.
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 1), [&](const tbb::blocked_range<int>& range) {
      for (int image = range.begin(); image < range.end(); ++image) {
        if (!measured[image] || all[image].given_median_px < gate) continue;
        TestFrame(samples[image], world_from_cam[image], intrinsics[image], explained_pair_px,
                  &all[image]);
        all[image].fitted = true;
      }
    });
  });
  std::vector<FrameFinding> findings;
  for (int image = 0; image < n; ++image) {
    if (!measured[image]) continue;
    FrameIntrinsicsTest& test = all[image];
    const double width = std::max(1, intrinsics[image].width);
    const bool material = std::abs(test.focal_factor - 1.0) >= kMinFocalChange ||
                          std::hypot(test.principal_shift_px[0], test.principal_shift_px[1]) >=
                              kMinPrincipalPointChange * width;
    test.named = test.fitted && material && test.given_median_px >= kMinIntrinsicsGivenPx &&
                 test.given_median_px >= kMinIntrinsicsImprovement * test.free_median_px;
    tests->push_back(test);
    if (!test.named) continue;
    findings.push_back(
        {image, "intrinsics",
         fmt::format("its matches fit {:.1f}x better (median {:.2f} -> {:.2f} px) with its focal "
                     "length x{:.3f} and its principal point moved ({:.0f}, {:.0f}) px: its "
                     "intrinsics are likely wrong",
                     test.given_median_px / std::max(test.free_median_px, 1e-12),
                     test.given_median_px, test.free_median_px, test.focal_factor,
                     test.principal_shift_px[0], test.principal_shift_px[1])});
  }
  return findings;
}

}  // namespace raytime

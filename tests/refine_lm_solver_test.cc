// The ray-time LM solver (refine/solve/ray_time_lm_solver.h): its Jacobians against numeric
// differentiation, its objective and minimum against Ceres' on the same problem, held images, and
// bit-identical results on any thread count.
#include "refine/solve/ray_time_lm_solver.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>

#include "refine/refine.h"
#include "refine/solve/arctan_loss.h"
#include "refine/solve/cross_projection_cost.h"
#include "refine/solve/pose_prior_cost.h"
#include "refine/solve/ray_geometry.h"
#include "refine/solve/ray_time_lm_kernel.h"
#include "refine/solve/similarity_retraction.h"
#include "testing/random_draws.h"
#include "testing/synthetic_scene.h"
#include "tests/expect_pose.h"
#include "tests/numeric_jacobian.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

Eigen::Matrix3d ExpRotation(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  if (angle == 0.0) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, phi / angle).toRotationMatrix();
}

struct Residual {
  Eigen::Matrix3d source_rotation;
  Eigen::Vector3d source_centre;
  double ray_time;
  Eigen::Matrix3d target_rotation;
  Eigen::Vector3d target_centre;
  Eigen::Vector4d pinhole;
  Eigen::Vector3d source_ray;
  Eigen::Vector2d target_undistorted;

  // The residual at the local parameters x = (φ_s, δO_s, δt, φ_t, δO_t) (13).
  Eigen::Vector2d At(const Eigen::Matrix<double, 13, 1>& x) const {
    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 6> js, jt;
    Eigen::Vector2d jd;
    CrossProjectionJacobian(ExpRotation(x.segment<3>(0)) * source_rotation,
                            source_centre + x.segment<3>(3), ray_time + x(6),
                            ExpRotation(x.segment<3>(7)) * target_rotation,
                            target_centre + x.segment<3>(10), pinhole, source_ray,
                            target_undistorted, &r, &js, &jd, &jt);
    return r;
  }
};

// Away from the optimum (residuals of tens of pixels), for random poses: the closed-form
// Jacobians equal central differences in the local parameters.
TEST(RayTimeLmSolverTest, JacobiansMatchNumericDifferentiation) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto draw = [&] { return u(rng); };
  for (int trial = 0; trial < 20; ++trial) {
    Residual res;
    res.source_rotation = ExpRotation(0.3 * DrawVector3(draw));
    res.source_centre = DrawVector3(draw);
    res.target_rotation = ExpRotation(0.3 * DrawVector3(draw));
    res.target_centre = Eigen::Vector3d(2.0, 0.0, 0.0) + 0.5 * DrawVector3(draw);
    res.ray_time = 10.0 + 5.0 * draw();
    res.pinhole << 1400.0 + 50 * draw(), 1380.0 + 50 * draw(), 768.0 + 20 * draw(),
        512.0 + 20 * draw();
    res.source_ray = Eigen::Vector3d(0.2 * draw(), 0.2 * draw(), 1.0).normalized();
    res.target_undistorted << 768.0 + 300 * draw(), 512.0 + 300 * draw();

    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 6> js, jt;
    Eigen::Vector2d jd;
    CrossProjectionJacobian(res.source_rotation, res.source_centre, res.ray_time,
                            res.target_rotation, res.target_centre, res.pinhole, res.source_ray,
                            res.target_undistorted, &r, &js, &jd, &jt);
    Eigen::Matrix<double, 2, 13> analytic;
    analytic << js, jd, jt;
    const Eigen::Matrix<double, 13, 1> zero = Eigen::Matrix<double, 13, 1>::Zero();
    EXPECT_LT((res.At(zero) - r).norm(), 1e-12);
    const Eigen::MatrixXd numeric = NumericJacobian(
        [&](const Eigen::VectorXd& x) { return res.At(Eigen::Matrix<double, 13, 1>(x)); },
        Eigen::VectorXd::Zero(13), 1e-6);
    for (int k = 0; k < 13; ++k) {
      EXPECT_LT((numeric.col(k) - analytic.col(k)).norm(), 1e-5 * (1.0 + numeric.col(k).norm()))
          << "trial " << trial << ", parameter " << k;
    }
  }
}

// The residual is written once (refine/solve/ray_geometry.h): the LM kernel, the closed-form Ceres
// cost and the automatic-differentiation cost give the same value for the same poses, the first two
// bit for bit (the LM is handed RotationFromQuaternion's matrices), autodiff to rounding (it
// undistorts the pixels itself; here without distortion).
TEST(RayTimeLmSolverTest, EveryVariantOfTheResidualHasTheSameValue) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto draw = [&] { return u(rng); };
  for (int trial = 0; trial < 20; ++trial) {
    double source_pose[kPoseBlockSize], target_pose[kPoseBlockSize];
    for (double* pose : {source_pose, target_pose}) {
      const Eigen::Quaterniond q = Eigen::Quaterniond(
          Eigen::AngleAxisd(0.3 * draw(), Eigen::Vector3d(draw(), draw(), draw()).normalized()));
      const Eigen::Vector3d centre = DrawVector3(draw);
      const double block[kPoseBlockSize] = {q.x(),      q.y(),      q.z(),     q.w(),
                                            centre.x(), centre.y(), centre.z()};
      std::copy(block, block + kPoseBlockSize, pose);
    }
    target_pose[kPoseCentreOffset] += 2.0;
    double intrinsics[kNumIntrinsics] = {1400.0 + 50 * draw(),
                                         1380.0 + 50 * draw(),
                                         768.0 + 20 * draw(),
                                         512.0 + 20 * draw(),
                                         0,
                                         0,
                                         0,
                                         0};
    const Eigen::Vector2d source_pixel(768.0 + 300 * draw(), 512.0 + 300 * draw());
    const Eigen::Vector2d target_pixel(768.0 + 300 * draw(), 512.0 + 300 * draw());
    double ray_time = 10.0 + 5.0 * draw();
    Eigen::Vector3d source_ray;
    PixelToUnitRay(intrinsics, source_pixel.data(), source_ray.data());

    // The LM kernel.
    Eigen::Matrix3d rotation[2];
    for (int k = 0; k < 2; ++k) {
      double R[9];
      RotationFromQuaternion(k == 0 ? source_pose : target_pose, R);
      rotation[k] = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(R);
    }
    Eigen::Vector2d lm, jd;
    Eigen::Matrix<double, 2, 6> js, jt;
    CrossProjectionJacobian(
        rotation[0], Eigen::Map<const Eigen::Vector3d>(source_pose + 4), ray_time, rotation[1],
        Eigen::Map<const Eigen::Vector3d>(target_pose + 4),
        Eigen::Vector4d(intrinsics[kFx], intrinsics[kFy], intrinsics[kCx], intrinsics[kCy]),
        source_ray, target_pixel, &lm, &js, &jd, &jt);

    // The closed-form Ceres cost (fixed intrinsics) and the automatic-differentiation one.
    std::unique_ptr<ceres::CostFunction> fixed(
        FixedIntrinsicsCrossProjectionCost::Create(source_ray, target_pixel, intrinsics));
    const double* fixed_parameters[] = {source_pose, &ray_time, target_pose};
    Eigen::Vector2d closed_form;
    ASSERT_TRUE(fixed->Evaluate(fixed_parameters, closed_form.data(), nullptr));
    std::unique_ptr<ceres::CostFunction> autodiff(
        CrossProjectionAutoDiffCost::Create(source_pixel, target_pixel));
    const double* autodiff_parameters[] = {intrinsics, source_pose, &ray_time, target_pose};
    Eigen::Vector2d automatic;
    ASSERT_TRUE(autodiff->Evaluate(autodiff_parameters, automatic.data(), nullptr));

    EXPECT_EQ(lm, closed_form) << "trial " << trial;
    EXPECT_LT((automatic - closed_form).norm(), 1e-9 * (1.0 + closed_form.norm()))
        << "trial " << trial;
    EXPECT_GT(closed_form.norm(), 1.0);  // away from the optimum: a value worth comparing
  }
}

// The pose prior's linearization, from the exact prior (θ = 0) to nearly half a turn, with the
// pose's quaternion in either sign: its residual is the Ceres functor's (PosePriorCost) and its
// Jacobian equals central differences in (φ, δO).
TEST(RayTimeLmSolverTest, PosePriorJacobianMatchesTheCeresTermAndNumericDifferentiation) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto draw = [&] { return u(rng); };
  const double position_weight = 0.7;
  const double orientation_weight = 1e3 / 11.0;
  const double centre_scale = std::sqrt(2.0 * position_weight);
  const double rotation_scale = std::sqrt(2.0 * orientation_weight);
  for (const double angle : {0.0, 1e-7, 1e-3, 0.3, 1.5, 3.0}) {
    for (const double sign : {1.0, -1.0}) {
      const Rigid3 prior(Eigen::Quaterniond(ExpRotation(DrawVector3(draw))),
                         3.0 * DrawVector3(draw));
      const Eigen::Vector3d axis = DrawVector3(draw).normalized();
      Eigen::Quaterniond rotation =
          Eigen::Quaterniond(prior.rotation.toRotationMatrix() * ExpRotation(angle * axis));
      rotation.coeffs() *= sign;
      const Rigid3 pose(rotation, prior.translation + 0.2 * DrawVector3(draw));

      Eigen::Matrix<double, 6, 1> residual;
      Eigen::Matrix<double, 6, 6> jacobian;
      PosePriorJacobian(pose, prior, rotation_scale, centre_scale, &residual, &jacobian);
      EXPECT_NEAR(residual.tail<3>().norm(), rotation_scale * angle, 1e-9 * rotation_scale);

      double block[kPoseBlockSize];
      for (int k = 0; k < 4; ++k) block[k] = pose.rotation.coeffs()[k];
      for (int k = 0; k < 3; ++k) block[kPoseCentreOffset + k] = pose.translation[k];
      double ceres_residual[6];
      ASSERT_TRUE(PosePriorCost(prior, position_weight, orientation_weight)(block, ceres_residual));
      for (int k = 0; k < 6; ++k) {
        EXPECT_NEAR(residual(k), ceres_residual[k], 1e-9) << "angle " << angle << ", row " << k;
      }

      const auto at = [&](const Eigen::Matrix<double, 6, 1>& x) {
        const Rigid3 moved(
            Eigen::Quaterniond(ExpRotation(x.head<3>()) * pose.rotation.toRotationMatrix()),
            pose.translation + x.tail<3>());
        Eigen::Matrix<double, 6, 1> r;
        Eigen::Matrix<double, 6, 6> unused;
        PosePriorJacobian(moved, prior, rotation_scale, centre_scale, &r, &unused);
        return r;
      };
      const Eigen::MatrixXd numeric = NumericJacobian(
          [&](const Eigen::VectorXd& x) { return at(Eigen::Matrix<double, 6, 1>(x)); },
          Eigen::VectorXd::Zero(6), 1e-6);
      for (int k = 0; k < 6; ++k) {
        EXPECT_LT((numeric.col(k) - jacobian.col(k)).norm(), 1e-6 * (1.0 + numeric.col(k).norm()))
            << "angle " << angle << ", sign " << sign << ", parameter " << k;
      }
    }
  }
}

SyntheticSceneOptions DistortedNoisyScene() {
  SyntheticSceneOptions options = ArcScene(8, 250, 0.5, 0.05, 1);
  options.distortion = true;
  return options;
}

double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return Eigen::AngleAxisd(a.conjugate() * b).angle();
}

// Both solvers minimize one objective: the same cost at the start of every stage's schedule (to
// rounding), and, converged tightly, the same minimum, with and without the orientation prior and
// for both parameterizations.
TEST(RayTimeLmSolverTest, ReachesCeresMinimumOfTheSameObjective) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  scene.input.prior_world_from_cam = JitterPoses(scene.ground_truth, 3.0, 0.3, 11);
  for (const RayTimeParameterization parameterization :
       {RayTimeParameterization::kPerObservation, RayTimeParameterization::kAnchored}) {
    for (const double orientation_weight : {0.0, 1e3}) {
      RefineOptions options;
      options.parameterization = parameterization;
      options.orientation_weight = orientation_weight;
      options.trust_region = false;
      options.inconsistent_pairs_test = false;
      options.function_tolerance = 1e-13;
      options.max_iterations = 300;
      options.num_threads = 1;
      RefineOutput lm_output, ceres_output;
      const RefineSummary lm = RefinePoses(scene.input, options, &lm_output);
      options.solver = RefineSolver::kCeres;
      const RefineSummary ceres = RefinePoses(scene.input, options, &ceres_output);
      const std::string label =
          std::string(NameOf(parameterization)) + ", λR " + std::to_string(orientation_weight);
      ASSERT_EQ(lm.passes[0].solver, "ray_time_lm") << label;
      ASSERT_EQ(ceres.passes[0].solver, "ceres") << label;
      ASSERT_EQ(lm.passes[0].stages.size(), ceres.passes[0].stages.size());
      // §3.4: Ceres' automatic ordering eliminates exactly the ray times, as this solver does.
      EXPECT_EQ(ceres.passes[0].elimination_group_size, ceres.passes[0].num_ray_times) << label;
      EXPECT_NEAR(lm.passes[0].stages[0].initial_cost, ceres.passes[0].stages[0].initial_cost,
                  1e-12 * ceres.passes[0].stages[0].initial_cost)
          << label;
      EXPECT_NEAR(lm.final_cost, ceres.final_cost, 1e-9 * ceres.final_cost) << label;
      for (size_t i = 0; i < lm_output.world_from_cam.size(); ++i) {
        EXPECT_LT(AngleBetween(lm_output.world_from_cam[i].rotation,
                               ceres_output.world_from_cam[i].rotation),
                  1e-7)
            << label << ", image " << i;
        EXPECT_LT(
            (lm_output.world_from_cam[i].translation - ceres_output.world_from_cam[i].translation)
                .norm(),
            1e-5)  // metres, in a scene 30 m across
            << label << ", image " << i;
      }
      // And without the orientation prior the minimum is the scene's: the relative rotations are
      // recovered from the 3° prior (the absolute ones keep the gauge of the prior's frame).
      if (orientation_weight > 0) continue;
      for (size_t i = 1; i < lm_output.world_from_cam.size(); ++i) {
        const Rigid3 solved = lm_output.world_from_cam[0].Inverse() * lm_output.world_from_cam[i];
        const Rigid3 truth = scene.ground_truth[0].Inverse() * scene.ground_truth[i];
        EXPECT_LT(AngleBetween(solved.rotation, truth.rotation) * 180.0 / M_PI, 0.2)
            << label << ", image " << i;
      }
    }
  }
}

// `solver` is the only switch (issue 31): ray_time_lm runs the ray-time LM whatever else is set,
// auto runs it where every intrinsic is held; turning the evaluation cache off no longer switches
// an auto solve to Ceres: a combination that cannot mean what it says is refused.
TEST(RayTimeLmSolverTest, SolverIsTheOnlySwitch) {
  // Which solver ran is the question, not where it ends: a small scene and a few iterations per
  // stage (the uncached Ceres solve of the full scene took 237 s under the sanitizers).
  SyntheticSceneOptions small = DistortedNoisyScene();
  small.num_cameras = 4;
  small.num_points = 60;
  SyntheticScene scene = MakeSyntheticScene(small);
  scene.input.prior_world_from_cam = JitterPoses(scene.ground_truth, 1.0, 0.1, 3);
  RefineOptions options;
  options.trust_region = false;
  options.num_threads = 1;
  options.max_iterations = 3;
  RefineOutput output;
  for (const RefineSolver solver : {RefineSolver::kAuto, RefineSolver::kRayTimeLm}) {
    options.solver = solver;
    EXPECT_EQ(RefinePoses(scene.input, options, &output).passes[0].solver, "ray_time_lm")
        << NameOf(solver);
  }
  options.solver = RefineSolver::kCeres;
  options.use_evaluation_cache = false;
  EXPECT_EQ(RefinePoses(scene.input, options, &output).passes[0].solver, "ceres");
  const auto refusal = [&](const RefineOptions& refused) {
    try {
      RefinePoses(scene.input, refused, &output);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  for (const RefineSolver solver : {RefineSolver::kAuto, RefineSolver::kRayTimeLm}) {
    options.solver = solver;
    EXPECT_NE(refusal(options).find("use_evaluation_cache: false"), std::string::npos)
        << NameOf(solver);
  }
  options.use_evaluation_cache = true;
  options.solver = RefineSolver::kRayTimeLm;
  options.refine_focal = true;
  EXPECT_NE(refusal(options).find("solver 'ray_time_lm' holds every intrinsic"), std::string::npos);
  options.solver = RefineSolver::kAuto;
  EXPECT_EQ(RefinePoses(scene.input, options, &output).passes[0].solver, "ceres")
      << "self-calibration runs on Ceres";
}

// An image no residual reaches is held at its start (its only term is the prior, whose minimum
// is there), and the others still converge; a held image does not enter the reduced system.
// Exact, undistorted residuals from the true points of `scene` with the poses starting at `start`
// (also the prior, centres only): every image except `held` sees every point it sees in the
// scene, and each point's ray time lives on its first such image.
RayTimeLmProblem ExactProblem(const SyntheticScene& scene, const std::vector<Rigid3>& start,
                              int held) {
  RayTimeLmProblem problem;
  problem.world_from_cam = start;
  problem.prior_world_from_cam = start;
  problem.held.assign(start.size(), false);
  problem.held[held] = true;
  problem.position_weight = 1e-2 / start.size();
  problem.orientation_weight = 0.0;
  const CameraIntrinsics& camera = scene.input.cameras[0];
  problem.pinhole.assign(start.size(), Eigen::Vector4d(camera.params[kFx], camera.params[kFy],
                                                       camera.params[kCx], camera.params[kCy]));
  for (size_t p = 0; p < scene.points.size(); ++p) {
    std::vector<int> images;
    for (int i = 0; i < static_cast<int>(start.size()); ++i) {
      if (i != held && scene.keypoint_of_point[i][p] >= 0) images.push_back(i);
    }
    if (images.size() < 2) continue;
    const int source = images[0];
    const Eigen::Vector3d in_source = scene.ground_truth[source].Inverse() * scene.points[p];
    const int ray_time = static_cast<int>(problem.ray_times.size());
    problem.ray_times.push_back(in_source.norm() * 1.05);
    for (size_t k = 1; k < images.size(); ++k) {
      const Eigen::Vector3d in_target = scene.ground_truth[images[k]].Inverse() * scene.points[p];
      RayTimeLmResidual r;
      r.source_image = source;
      r.ray_time = ray_time;
      r.target_image = images[k];
      r.source_ray = in_source.normalized();
      r.target_undistorted << camera.params[kFx] * in_target.x() / in_target.z() +
                                  camera.params[kCx],
          camera.params[kFy] * in_target.y() / in_target.z() + camera.params[kCy];
      problem.residuals.push_back(r);
    }
  }
  problem.match_loss_weight = 1.0 / problem.residuals.size();
  return problem;
}

TEST(RayTimeLmSolverTest, HoldsImagesWithoutResiduals) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 1.0, 0.1, 5);
  RayTimeLmProblem problem = ExactProblem(scene, start, 2);
  ASSERT_GT(problem.residuals.size(), 100u);
  GncSettings settings;
  settings.scales = {1e4, 1e3, 1e2};
  settings.function_tolerance = 1e-12;
  const std::vector<GncStageSummary> stages = SolveGncRayTimeLm(&problem, settings);
  ASSERT_EQ(stages.size(), 3u);
  EXPECT_EQ(problem.world_from_cam[2].rotation.coeffs(), start[2].rotation.coeffs());
  EXPECT_EQ(problem.world_from_cam[2].translation, start[2].translation);
  EXPECT_LT(stages.back().final_cost, 1e-3 * stages.front().initial_cost);
  // Up to the gauge the prior's centres pin (a similarity), the relative poses are the truth's.
  const Rigid3 a = problem.world_from_cam[0].Inverse() * problem.world_from_cam[1];
  const Rigid3 b = scene.ground_truth[0].Inverse() * scene.ground_truth[1];
  EXPECT_LT(AngleBetween(a.rotation, b.rotation) * 180.0 / M_PI, 1e-3);
}

// The linearization folds a ray time's elimination into its cameras' blocks when each camera of
// its group appears once (one match per image pair), and adds the products separately when one
// appears twice. Every residual written twice at half the weight is the same objective, hence
// the same steps, through the second path: the two solutions agree to rounding.
TEST(RayTimeLmSolverTest, RepeatedTargetsTakeTheUnfoldedPathToTheSameSolution) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 2.0, 0.2, 7);
  RayTimeLmProblem once = ExactProblem(scene, start, 2);
  once.orientation_weight = 1.0 / start.size();
  RayTimeLmProblem twice = once;
  twice.residuals.clear();
  for (const RayTimeLmResidual& r : once.residuals) {
    twice.residuals.push_back(r);
    twice.residuals.push_back(r);
  }
  twice.match_loss_weight = 0.5 * once.match_loss_weight;
  GncSettings settings;
  settings.scales = {1e4, 1e3, 1e2};
  const std::vector<GncStageSummary> a = SolveGncRayTimeLm(&once, settings);
  const std::vector<GncStageSummary> b = SolveGncRayTimeLm(&twice, settings);
  ASSERT_EQ(a.size(), b.size());
  for (size_t s = 0; s < a.size(); ++s) {
    EXPECT_EQ(a[s].iterations, b[s].iterations) << "stage " << s;
    EXPECT_NEAR(a[s].final_cost, b[s].final_cost, 1e-12 * a[s].final_cost) << "stage " << s;
  }
  double max_angle = 0.0;
  double max_centre = 0.0;
  for (size_t i = 0; i < start.size(); ++i) {
    max_angle = std::max(
        max_angle, AngleBetween(once.world_from_cam[i].rotation, twice.world_from_cam[i].rotation));
    max_centre =
        std::max(max_centre,
                 (once.world_from_cam[i].translation - twice.world_from_cam[i].translation).norm());
  }
  EXPECT_LT(max_angle, 1e-10);
  EXPECT_LT(max_centre, 1e-10);
  // And the solve moved: the start was 2° off.
  EXPECT_GT(AngleBetween(once.world_from_cam[0].rotation, start[0].rotation), 1e-3);
}

TEST(RayTimeLmSolverTest, RefusesARayTimeWhoseResidualsStartFromTwoObservations) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  RayTimeLmProblem problem = ExactProblem(scene, scene.ground_truth, 2);
  // Find a ray time with two residuals and move the second one's source ray.
  size_t k = 1;
  while (k < problem.residuals.size() &&
         problem.residuals[k].ray_time != problem.residuals[k - 1].ray_time) {
    ++k;
  }
  ASSERT_LT(k, problem.residuals.size());
  problem.residuals[k].source_ray = Eigen::Vector3d(0.0, 0.0, 1.0);
  GncSettings settings;
  settings.scales = {1e2};
  EXPECT_THROW(SolveGncRayTimeLm(&problem, settings), std::invalid_argument);
}

// The ray-time update is the Gauss–Newton step taken in inverse depth. A point on the source's
// optical axis seen by a target 1 m to the side projects at u = -f·b/t, linear in 1/t: from
// either side of the true depth one step lands on it, where t + δ undershoots from near and, from
// far, crosses the camera (clamped to the bound).
TEST(RayTimeLmSolverTest, RayTimeStepIsExactInInverseDepth) {
  const double truth = 1000.0;
  const Eigen::Vector4d pinhole(1000.0, 1000.0, 0.0, 0.0);
  const Eigen::Vector3d target_centre(1.0, 0.0, 0.0);
  const Eigen::Vector2d observed(-pinhole[0] * target_centre.x() / truth, 0.0);
  for (const double start : {200.0, 10000.0}) {
    Eigen::Vector2d r, jd;
    Eigen::Matrix<double, 2, 6> js, jt;
    CrossProjectionJacobian(Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), start,
                            Eigen::Matrix3d::Identity(), target_centre, pinhole,
                            Eigen::Vector3d::UnitZ(), observed, &r, &js, &jd, &jt);
    const double step = -jd.dot(r) / jd.squaredNorm();
    EXPECT_NEAR(RetractRayTime(start, step), truth, 1e-9 * truth) << "from " << start;
    EXPECT_GT(std::abs(std::max(start + step, kRayTimeLowerBound) - truth), 0.5 * truth)
        << "from " << start;
  }
  // Small steps are t + δ to second order; a step toward the camera never crosses it; a step
  // beyond 1/t = 0 moves at most kMaxRayTimeGrowth times further.
  EXPECT_NEAR(RetractRayTime(10.0, 1e-4), 10.0 + 1e-4, 2e-9);
  EXPECT_NEAR(RetractRayTime(5.0, -100.0), 5.0 / 21.0, 1e-15);
  EXPECT_EQ(RetractRayTime(5.0, 100.0), 5.0 * kMaxRayTimeGrowth);
  EXPECT_EQ(RetractRayTime(kRayTimeLowerBound, -1.0), kRayTimeLowerBound);
}

// A point far out along its ray (a ray time of 1e12 in a scene 30 m across, as matches on distant
// structure drift) does not stop the solve: the parameter tolerance weighs the poses, not |t|,
// which here would have let a 1e4-long step count as "no change" and stopped at the jittered start.
TEST(RayTimeLmSolverTest, AFarRayTimeDoesNotStopTheSolve) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 1.0, 0.1, 5);
  RayTimeLmProblem problem = ExactProblem(scene, start, 2);
  // A direction seen from image 0 and observed at its vanishing point in image 1.
  const Eigen::Vector3d direction = Eigen::Vector3d(0.05, -0.02, 1.0).normalized();
  const Eigen::Vector3d in_target =
      scene.ground_truth[1].rotation.inverse() * (scene.ground_truth[0].rotation * direction);
  RayTimeLmResidual far;
  far.source_image = 0;
  far.ray_time = static_cast<int>(problem.ray_times.size());
  far.target_image = 1;
  far.source_ray = direction;
  far.target_undistorted << problem.pinhole[1][0] * in_target.x() / in_target.z() +
                                problem.pinhole[1][2],
      problem.pinhole[1][1] * in_target.y() / in_target.z() + problem.pinhole[1][3];
  problem.ray_times.push_back(1e12);
  problem.residuals.push_back(far);
  problem.match_loss_weight = 1.0 / problem.residuals.size();
  GncSettings settings;
  settings.scales = {1e4, 1e3, 1e2};
  settings.function_tolerance = 1e-12;
  const std::vector<GncStageSummary> stages = SolveGncRayTimeLm(&problem, settings);
  ASSERT_EQ(stages.size(), 3u);
  EXPECT_GT(stages[0].iterations, 2);
  const Rigid3 a = problem.world_from_cam[0].Inverse() * problem.world_from_cam[1];
  const Rigid3 b = scene.ground_truth[0].Inverse() * scene.ground_truth[1];
  EXPECT_LT(AngleBetween(a.rotation, b.rotation) * 180.0 / M_PI, 1e-3);
}

// The arctan loss's sum (the vector atan where the CPU has AVX2) against the scalar atan2 of the
// loss as Ceres writes it: squared norms from 0 to 1e12 px², lengths that are not a multiple of 4.
TEST(RayTimeLmSolverTest, SumOfArctansIsTheLossSum) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> exponent(-6.0, 12.0);
  for (const int n : {0, 1, 3, 4, 5, 257}) {
    std::vector<double> s(n);
    for (double& v : s) v = std::pow(10.0, exponent(rng));
    if (n > 2) s[1] = 0.0;
    for (const double a : {0.25, 1.37, 100.0, 1e4}) {
      double expected = 0.0;
      for (const double v : s) expected += std::atan2(v, a);
      EXPECT_NEAR(SumOfArctans(s.data(), n, a), expected, 1e-14 * std::max(1.0, expected))
          << n << " values, a = " << a;
    }
  }
}

// A step that is a global similarity (the match term cannot see it) is taken as that similarity,
// exactly, however large, also in far coordinates (about the cameras' centroid); the plain update
// is one only to first order. A camera outside the step keeps its pose. For any small step the
// two updates agree to second order.
TEST(RayTimeLmSolverTest, ASimilarityStepIsTakenAsASimilarity) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Rigid3> poses(5);
  for (Rigid3& pose : poses) {
    pose.rotation = DrawQuaternion([&] { return u(rng); }).normalized();
    pose.translation = 3.0 * DrawVector3([&] { return u(rng); });
  }
  const std::vector<int> variable = {0, 1, -1, 2, 3};
  // A prior in far coordinates (UTM metres): the pivot is the cameras' centroid.
  for (Rigid3& pose : poses) pose.translation += Eigen::Vector3d(4.5e5, 5.2e6, 30.0);
  const Eigen::Vector3d pivot = SimilarityPivot(poses, variable);
  const Eigen::Vector3d centroid =
      (poses[0].translation + poses[1].translation + poses[3].translation + poses[4].translation) /
      4.0;
  EXPECT_LT((pivot - centroid).norm(), 1e-9);
  Eigen::Matrix<double, 7, 1> similarity;
  similarity << 0.1, -0.05, 0.2, 0.1, 0.3, -0.2, 0.1;  // ω (rad), λ = log scale, τ
  Eigen::VectorXd step(24);
  for (size_t i = 0; i < poses.size(); ++i) {
    if (variable[i] >= 0) {
      step.segment<6>(6 * variable[i]) =
          SimilarityTangent(poses[i].translation - pivot) * similarity;
    }
  }
  EXPECT_LT((SimilarityPart(poses, variable, step) - similarity).norm(), 1e-9);

  std::vector<Rigid3> moved = poses;
  RetractPoses(variable, step, similarity, &moved);
  const Eigen::Quaterniond rotation(
      Eigen::AngleAxisd(similarity.head<3>().norm(), similarity.head<3>().normalized()));
  const double scale = std::exp(similarity[3]);
  for (size_t i = 0; i < poses.size(); ++i) {
    if (variable[i] < 0) {
      EXPECT_EQ(moved[i].rotation.coeffs(), poses[i].rotation.coeffs());
      EXPECT_EQ(moved[i].translation, poses[i].translation);
      continue;
    }
    EXPECT_LT(AngleBetween(moved[i].rotation, rotation * poses[i].rotation), 1e-12) << i;
    const Eigen::Vector3d expected =
        pivot + scale * (rotation * (poses[i].translation - pivot)) + similarity.tail<3>();
    EXPECT_LT((moved[i].translation - expected).norm(), 1e-8) << i;
  }
  std::vector<Rigid3> plain = poses;
  RetractPoses(variable, step, Eigen::Matrix<double, 7, 1>::Zero(), &plain);
  EXPECT_GT((plain[0].translation - moved[0].translation).norm(), 1e-2)
      << "the plain update is a similarity only to first order";

  Eigen::VectorXd small(24);
  for (int k = 0; k < small.size(); ++k) small[k] = 1e-4 * u(rng);
  std::vector<Rigid3> split = poses;
  RetractPoses(variable, small, SimilarityPart(poses, variable, small), &split);
  std::vector<Rigid3> linear = poses;
  RetractPoses(variable, small, Eigen::Matrix<double, 7, 1>::Zero(), &linear);
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_LT(AngleBetween(split[i].rotation, linear[i].rotation), 1e-7) << i;
    EXPECT_LT((split[i].translation - linear[i].translation).norm(), 1e-7) << i;
    if (variable[i] >= 0) {
      EXPECT_GT((split[i].translation - poses[i].translation).norm(), 1e-5) << "it moved";
    }
  }
}

// Step doubling (GncSettings::max_step_doublings): at a small arctan scale with a third of the
// points' matches up to 2 px off, the IRLS steps fall short of the minimum along their direction
// (the plain solve took 28 steps at a = 1 px², the doubled one 16); the doubled steps reach the
// same solution (up to the similarity the weak prior holds), a little further down.
TEST(RayTimeLmSolverTest, DoubledStepsReachTheSameSolutionSooner) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 1.0, 0.05, 9);
  RayTimeLmProblem problem = ExactProblem(scene, start, 2);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (RayTimeLmResidual& r : problem.residuals) {
    if (r.ray_time % 3 == 0) r.target_undistorted += 2.0 * DrawVector2([&] { return u(rng); });
  }
  RayTimeLmProblem doubled = problem;
  GncSettings settings;
  settings.scales = {1e2, 1.0};
  settings.function_tolerance = 1e-12;
  settings.max_step_doublings = 0;
  const std::vector<GncStageSummary> plain_stages = SolveGncRayTimeLm(&problem, settings);
  settings.max_step_doublings = 3;
  const std::vector<GncStageSummary> doubled_stages = SolveGncRayTimeLm(&doubled, settings);
  int plain_iterations = 0;
  int doubled_iterations = 0;
  int doublings = 0;
  for (const GncStageSummary& stage : plain_stages) {
    plain_iterations += stage.iterations;
    EXPECT_EQ(stage.step_doublings, 0);
  }
  for (const GncStageSummary& stage : doubled_stages) {
    doubled_iterations += stage.iterations;
    doublings += stage.step_doublings;
  }
  EXPECT_GT(doublings, 0);
  EXPECT_LT(doubled_iterations, plain_iterations);
  EXPECT_LE(doubled_stages.back().final_cost, plain_stages.back().final_cost * (1 + 1e-9));
  for (size_t i = 1; i < start.size(); ++i) {
    const Rigid3 a = doubled.world_from_cam[0].Inverse() * doubled.world_from_cam[i];
    const Rigid3 b = problem.world_from_cam[0].Inverse() * problem.world_from_cam[i];
    EXPECT_LT(AngleBetween(a.rotation, b.rotation) * 180.0 / M_PI, 1e-4) << "image " << i;
  }
}

// Bit-identical on any thread count (fixed chunks summed in a fixed order), including the ray
// times and the pose uncertainty.
TEST(RayTimeLmSolverTest, SameBitsOnAnyThreadCount) {
  SyntheticScene scene = MakeSyntheticScene(DistortedNoisyScene());
  scene.input.prior_world_from_cam = JitterPoses(scene.ground_truth, 4.0, 0.4, 3);
  RefineOptions options = BasinConfiguration(0);
  options.num_threads = 1;
  RefineOutput first;
  const RefineSummary reference = RefinePoses(scene.input, options, &first);
  ASSERT_EQ(reference.passes[0].solver, "ray_time_lm");
  for (const int threads : {2, 3, 8}) {
    options.num_threads = threads;
    RefineOutput again;
    const RefineSummary summary = RefinePoses(scene.input, options, &again);
    EXPECT_EQ(summary.final_cost, reference.final_cost) << threads << " threads";
    EXPECT_EQ(summary.total_iterations, reference.total_iterations) << threads << " threads";
    ExpectSamePoses(again.world_from_cam, first.world_from_cam,
                    std::to_string(threads) + " threads");
    ASSERT_EQ(first.solved_observations.ray_times.size(),
              again.solved_observations.ray_times.size());
    for (Eigen::Index o = 0; o < first.solved_observations.ray_times.size(); ++o) {
      ASSERT_EQ(first.solved_observations.ray_times(o), again.solved_observations.ray_times(o))
          << "observation " << o;
    }
    // The pose uncertainty too (its two passes run over fixed chunks).
    ASSERT_TRUE(reference.uncertainty.computed);
    for (size_t i = 0; i < reference.uncertainty.cameras.size(); ++i) {
      EXPECT_EQ(summary.uncertainty.cameras[i].rotation_deg,
                reference.uncertainty.cameras[i].rotation_deg)
          << threads << " threads, image " << i;
      EXPECT_EQ(summary.uncertainty.cameras[i].centre, reference.uncertainty.cameras[i].centre)
          << threads << " threads, image " << i;
    }
  }
}

}  // namespace
}  // namespace raytime

// The synthetic capture generator of the scaling benchmark (testing/synthetic_capture.cc, issue 14)
// end to end: its files are raytime's schema (the raytime binary refines them), its prior is the
// ladder's perturbation of its ground truth, and the all-match solve on the ray-time LM solver
// recovers the ground truth from it.
#include <gtest/gtest.h>

#include <cstdio>
#include <nlohmann/json.hpp>

#include "core/hdf5_store.h"
#include "evaluate/pose_errors.h"
#include "tests/raytime_command.h"
#include "tests/temp_dir.h"

namespace raytime {
namespace {

TEST(SyntheticCapture, RefinesBackToItsGroundTruth) {
  TempDir dir("synthetic_capture");
  const CommandResult generated =
      RunShell(std::string(RAYTIME_SYNTHETIC_CAPTURE) + " --cameras 40 --keypoints 400 --window 6" +
               " --level 4 --seed 3 --out " + dir.path().string());
  ASSERT_EQ(generated.exit_code, 0) << generated.output;
  const nlohmann::json counts = nlohmann::json::parse(generated.output);
  EXPECT_EQ(counts["cameras"], 40);
  // Every frame is matched with the next 6: 40 * 6 - (1 + ... + 6) pairs.
  EXPECT_EQ(counts["pairs"], 40 * 6 - 21);
  EXPECT_GT(counts["matches"].get<int>(), 40 * 6 * 100);

  const CommandResult refined =
      RunRaytime("refine --in " + dir / "dataset.h5" + " " + dir / "features.h5" + " " +
                 dir / "matches.h5" + " " + dir / "prior.h5" +
                 " --preset basin --max_matches_per_pair 0 --out " + dir / "refine.h5");
  ASSERT_EQ(refined.exit_code, 0) << refined.output;
  EXPECT_NE(refined.output.find("solver ray_time_lm"), std::string::npos) << refined.output;

  const PoseSet truth = Hdf5Reader(dir / "dataset.h5").ReadPoseSet("ground_truth");
  const PoseSet prior = Hdf5Reader(dir / "prior.h5").ReadPoseSet("prior");
  const PoseSet solved = Hdf5Reader(dir / "refine.h5").ReadPoseSet("refined");
  ASSERT_EQ(solved.size(), 40u);
  const PoseErrorOptions sim3;
  const PoseErrorSummary before = ComputePoseErrors(prior, truth, sim3);
  const PoseErrorSummary after = ComputePoseErrors(solved, truth, sim3);
  // Relative rotations: a sweep's nearly collinear centres leave a Sim(3) fit on them free to
  // turn the frame by tenths of a degree (evaluate/pose_errors.h).
  EXPECT_GT(before.median_relative_rotation_deg, 3.0);
  EXPECT_LT(after.median_relative_rotation_deg, 0.05);
  std::printf("synthetic capture: relative rotation median %.3f -> %.4f deg, Sim(3) mean %.3f\n",
              before.median_relative_rotation_deg, after.median_relative_rotation_deg,
              after.mean_rotation_deg);
}

}  // namespace
}  // namespace raytime

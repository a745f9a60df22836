// The match term's robust loss (paper §3.5): Ceres' ArctanLoss scaled by the match weight, its
// derivative for the IRLS weights, and its sum over many residuals with a vectorised atan.
#pragma once

namespace raytime {

// The match term's loss: Ceres' ArctanLoss(a) scaled by w (RayTimeProblem's), ρ(s) = w·a·atan(s/a)
// (summed by SumOfArctans) and ρ'(s) of s = |r|². The ray-time LM (ray_time_lm_solver.h) and the
// uncertainty at its solution (refine/checks/pose_uncertainty.h) weigh with it.
struct ScaledArctanLoss {
  double scale;   // a, px²
  double weight;  // w = 2/S
  double Derivative(double s) const { return weight * scale * scale / (s * s + scale * scale); }
};

// Σ atan(s_k / a) over s[0..n) (s_k ≥ 0, a > 0): the arctan loss's sum without its factor w·a
// (ScaledArctanLoss). Where the CPU has AVX2, four at a time with glibc's vector atan (libmvec,
// within a few ulp of atan): the scalar atan2 was a sizeable share of a whole refine, the vector
// one a tenth of its cost (measured: docs/scaling.md, "Measurements behind the LM's choices").
// Deterministic on a machine, whatever the thread count; a CPU without AVX2 takes the scalar atan
// and may differ in the last bits.
double SumOfArctans(const double* s, int n, double scale);

}  // namespace raytime

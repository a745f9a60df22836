#include "refine/solve/ray_time_lm_linearization.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "refine/solve/fixed_chunks.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {
namespace {

// block += s·a·bᵀ, 6x6 row-major.
inline void AddScaledOuter(double* __restrict block, const double* __restrict a,
                           const double* __restrict b, double s) {
  for (int i = 0; i < 6; ++i) {
    const double ai = s * a[i];
    for (int j = 0; j < 6; ++j) block[6 * i + j] += ai * b[j];
  }
}

// The lower triangle (j <= i) of block += s·a·aᵀ: a camera's diagonal block is symmetric and
// only its lower triangle is assembled, so the upper one is never accumulated.
inline void AddScaledLowerOuter(double* __restrict block, const double* __restrict a, double s) {
  for (int i = 0; i < 6; ++i) {
    const double ai = s * a[i];
    for (int j = 0; j <= i; ++j) block[6 * i + j] += ai * a[j];
  }
}

// The structured linearization. A residual's Jacobians all factor through M = ∂r/∂X (2x3, the
// target projection's derivative at the ray point X): the source pose's rows are B_s·m_a with
// B_s = [[o]×; I] (o = t·R_s·d, the ray point's offset from the source centre), the target's
// -[[v]×; I]·m_a (v = X - O_t) and the ray time's dᵀ·m_a (d = R_s·d_cam), m_a the rows of M. So
// with Q = w·MᵀM (3x3) and q = w·Mᵀr every product the reduced system needs is B·Q·Bᵀ, B·q or
// B·Q·d, fewer operations than forming the 2x6 Jacobians and their products, and all of a ray
// time's residuals share its source lever B_s, so the source's terms are summed as Q and applied
// once per ray time (measured: docs/scaling.md, "The LM's linearization kernel").

// p = [x]×·Q for a symmetric 3x3 Q (row-major).
inline void SkewTimes(const double* x, const double* q, double* p) {
  for (int j = 0; j < 3; ++j) {
    p[j] = x[1] * q[6 + j] - x[2] * q[3 + j];
    p[3 + j] = x[2] * q[j] - x[0] * q[6 + j];
    p[6 + j] = x[0] * q[3 + j] - x[1] * q[j];
  }
}

// out = x × y.
inline void Cross(const double* x, const double* y, double* out) {
  out[0] = x[1] * y[2] - x[2] * y[1];
  out[1] = x[2] * y[0] - x[0] * y[2];
  out[2] = x[0] * y[1] - x[1] * y[0];
}

// The lower triangle of block += B·Q·Bᵀ for B = [[x]×; I] (6x3), given p = [x]×·Q, and its
// diagonal into `diagonal`: [[x]×Q[x]×ᵀ, ·; Q[x]×ᵀ, Q], whose row i of [x]×Q[x]×ᵀ is x × p_i.
// Written out entry by entry: a temporary row array that the compiler then read back as packed
// pairs stalled on store forwarding (perf: the hottest instructions of the linearization).
inline void AddLeverGram(const double* x, const double* q, const double* p, double* block,
                         double* diagonal) {
  const double r00 = x[1] * p[2] - x[2] * p[1];
  const double r10 = x[1] * p[5] - x[2] * p[4];
  const double r11 = x[2] * p[3] - x[0] * p[5];
  const double r20 = x[1] * p[8] - x[2] * p[7];
  const double r21 = x[2] * p[6] - x[0] * p[8];
  const double r22 = x[0] * p[7] - x[1] * p[6];
  block[0] += r00;
  block[6] += r10;
  block[7] += r11;
  block[12] += r20;
  block[13] += r21;
  block[14] += r22;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) block[6 * (3 + i) + j] += p[3 * j + i];
  }
  block[21] += q[0];
  block[27] += q[3];
  block[28] += q[4];
  block[33] += q[6];
  block[34] += q[7];
  block[35] += q[8];
  diagonal[0] += r00;
  diagonal[1] += r11;
  diagonal[2] += r22;
  diagonal[3] += q[0];
  diagonal[4] += q[4];
  diagonal[5] += q[8];
}

// out = B·y for B = [[x]×; I] scaled by `sign`, added to the 6-vector out.
inline void AddLeverTimes(const double* x, const double* y, double sign, double* out) {
  double top[3];
  Cross(x, y, top);
  for (int a = 0; a < 3; ++a) {
    out[a] += sign * top[a];
    out[3 + a] += sign * y[a];
  }
}

// y = Q·x for a 3x3 row-major Q.
inline void Times3(const double* q, const double* x, double* y) {
  for (int a = 0; a < 3; ++a) y[a] = q[3 * a] * x[0] + q[3 * a + 1] * x[1] + q[3 * a + 2] * x[2];
}

// One residual's target terms within its ray time: the target camera (variable), the residual,
// v = X - O_t, Q = w·MᵀM, and Q·d.
struct TargetTerm {
  int camera = -1;
  int residual = -1;
  double v[3];
  double q[9];
  double qd[3];
};

// Adds the source-target block B_s·Z·B_tᵀ = -[[o]×·R, [o]×·Z; R, Z] (source rows i, target
// columns j) to block[i·row_stride + j·column_stride], with B_s = [[o]×; I], B_t = -[[v]×; I] and
// R = Z·[v]×ᵀ, whose row i is v × z_i: strides (6, 1) when the source is the block's row camera,
// (1, 6) when it is the column camera. Added in place: a 6x6 temporary added afterwards stalled on
// store forwarding.
inline void AddSourceTargetCoupling(const double* o, const double* v, const double* z,
                                    double* block, int row_stride, int column_stride) {
  double r[9];
  for (int i = 0; i < 3; ++i) {
    const double* zi = z + 3 * i;
    r[3 * i] = v[1] * zi[2] - v[2] * zi[1];
    r[3 * i + 1] = v[2] * zi[0] - v[0] * zi[2];
    r[3 * i + 2] = v[0] * zi[1] - v[1] * zi[0];
  }
  for (int j = 0; j < 3; ++j) {
    // Column j of [o]×·R and of [o]×·Z: o × (column j).
    const double r0 = r[j], r1 = r[3 + j], r2 = r[6 + j];
    const double z0 = z[j], z1 = z[3 + j], z2 = z[6 + j];
    double* left = block + j * column_stride;
    double* right = block + (3 + j) * column_stride;
    left[0] -= o[1] * r2 - o[2] * r1;
    left[row_stride] -= o[2] * r0 - o[0] * r2;
    left[2 * row_stride] -= o[0] * r1 - o[1] * r0;
    right[0] -= o[1] * z2 - o[2] * z1;
    right[row_stride] -= o[2] * z0 - o[0] * z2;
    right[2 * row_stride] -= o[0] * z1 - o[1] * z0;
    left[3 * row_stride] -= r0;
    left[4 * row_stride] -= r1;
    left[5 * row_stride] -= r2;
    right[3 * row_stride] -= z0;
    right[4 * row_stride] -= z1;
    right[5 * row_stride] -= z2;
  }
}

// What every ray time's linearization reads.
struct LinearizationInputs {
  const RayTimeLmProblem& problem;
  const RayTimeLmPoint& point;
  const ScaledArctanLoss& loss;
  double radius;
};

// One ray time's terms as its linearization gathers them: its group of cameras with their
// couplings H_ct, the source camera (variable), the ray direction d and the lever o = t·d, the
// source's terms summed over the residuals (Q = Σ w·MᵀM, q = Σ w·Mᵀr, Q·d) and the variable
// targets' terms; then the ray time's curvature h_tt and gradient g_t.
struct RayTimeTerms {
  const int* group = nullptr;
  int group_size = 0;
  Row6* coupling = nullptr;
  int source_camera = -1;
  double dir[3];
  double lever[3];
  double source_q[9];
  double source_g[3];
  double source_qd[3];
  double h_tt = 0.0;
  double g_t = 0.0;
  std::vector<TargetTerm> targets;

  // The coupling H_ct of a camera of the group.
  double* Slot(int camera) const {
    return coupling[std::lower_bound(group, group + group_size, camera) - group].data();
  }
};

// The ray time's residuals at the point: each target's terms, its gradient and its share of the
// coupling, and the source's sums.
[[gnu::always_inline]] inline void GatherResiduals(const LinearizationInputs& in,
                                                   const ReducedCameraPattern& pattern, int t,
                                                   RayTimeTerms* rt,
                                                   ReducedCameraSystem::Partial* partial) {
  const RayTimeLmPoint& x = in.point;
  // The ray time's observation: its residuals share the source image and ray (the problem's
  // contract, checked when the pattern is built), hence the ray point and the source lever.
  const RayTimeLmResidual& first = in.problem.residuals[pattern.residual_begin(t)];
  const int source = first.source_image;
  rt->source_camera = pattern.variable(source);
  double point[3];
  RayPoint(x.rotation[source].data(), x.centre[source].data(), x.ray_times[t],
           first.source_ray.data(), rt->dir, point);
  for (int a = 0; a < 3; ++a) rt->lever[a] = x.ray_times[t] * rt->dir[a];
  std::fill(rt->source_q, rt->source_q + 9, 0.0);
  std::fill(rt->source_g, rt->source_g + 3, 0.0);
  rt->targets.clear();
  for (int k = pattern.residual_begin(t); k < pattern.residual_end(t); ++k) {
    const RayTimeLmResidual& r = in.problem.residuals[k];
    const int target = r.target_image;
    TargetTerm term;
    double p_cam[3], e[2];
    TargetResidual(x.rotation[target].data(), x.centre[target].data(),
                   in.problem.pinhole[target].data(), point, r.target_undistorted.data(), term.v,
                   p_cam, e);
    const TargetResidualDerivative derivative = DifferentiateTargetResidual(
        x.rotation[target].data(), in.problem.pinhole[target].data(), p_cam);
    const double* m0 = derivative.du_dX[0];
    const double* m1 = derivative.du_dX[1];
    const double w = in.loss.Derivative(e[0] * e[0] + e[1] * e[1]);
    double g[3];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j <= i; ++j) {
        term.q[3 * i + j] = term.q[3 * j + i] = w * (m0[i] * m0[j] + m1[i] * m1[j]);
      }
      g[i] = w * (m0[i] * e[0] + m1[i] * e[1]);
    }
    for (int a = 0; a < 9; ++a) rt->source_q[a] += term.q[a];
    for (int a = 0; a < 3; ++a) rt->source_g[a] += g[a];
    term.camera = pattern.variable(target);
    if (term.camera < 0) continue;
    term.residual = k;
    Times3(term.q, rt->dir, term.qd);
    AddLeverTimes(term.v, g, -1.0, partial->gradient[term.camera].data());
    AddLeverTimes(term.v, term.qd, -1.0, rt->Slot(term.camera));
    rt->targets.push_back(term);
  }
}

// The ray time's own curvature and gradient, its projected gradient's norm, and the source
// camera's gradient and share of the coupling.
[[gnu::always_inline]] inline void AddSourceTerms(const LinearizationInputs& in, int t,
                                                  RayTimeTerms* rt, ReducedCameraSystem* system,
                                                  ReducedCameraSystem::Partial* partial) {
  const double* dir = rt->dir;
  Times3(rt->source_q, dir, rt->source_qd);
  const double* qd = rt->source_qd;
  const double* g = rt->source_g;
  rt->h_tt = dir[0] * qd[0] + dir[1] * qd[1] + dir[2] * qd[2];
  rt->g_t = dir[0] * g[0] + dir[1] * g[1] + dir[2] * g[2];
  system->SetRayTime(t, rt->g_t, rt->h_tt);
  const double t_value = in.point.ray_times[t];
  const double projected = std::max(t_value - rt->g_t, kRayTimeLowerBound);
  partial->gradient_max_norm = std::max(partial->gradient_max_norm, std::abs(t_value - projected));
  const int cs = rt->source_camera;
  if (cs >= 0) {
    AddLeverTimes(rt->lever, rt->source_g, 1.0, partial->gradient[cs].data());
    AddLeverTimes(rt->lever, rt->source_qd, 1.0, rt->Slot(cs));
  }
}

// Eliminates the ray time from the camera blocks: S -= H_ct H_tc / h̃ with H_ct = B_c·Q·d. When
// every camera of the group is one residual's target or the source (`folded`: the layouts'
// matches, one per image pair), the elimination's share of a camera's own block and of the
// source-target coupling folds into the 3x3 middle factor, B·(Q - Q·d·dᵀ·Q'/h̃)·Bᵀ, which is added
// once instead of the product and the correction separately.
[[gnu::always_inline]] inline void FoldElimination(const RayTimeTerms& rt, double inverse,
                                                   bool folded, const ReducedCameraPattern& pattern,
                                                   ReducedCameraSystem::Partial* partial) {
  const int cs = rt.source_camera;
  double z[9], p[9];
  auto fold = [&](const double* q, const double* left, const double* right) {
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        z[3 * i + j] = q[3 * i + j] - (folded ? left[i] * right[j] * inverse : 0.0);
      }
    }
  };
  auto add_diagonal_of_elimination = [&](int camera, const double* coupling_row) {
    // The damping's diag(JᵀJ) is the block's before the elimination.
    if (!folded) return;
    for (int a = 0; a < 6; ++a) {
      partial->diagonal[camera][a] += coupling_row[a] * coupling_row[a] * inverse;
    }
  };
  if (cs >= 0) {
    fold(rt.source_q, rt.source_qd, rt.source_qd);
    SkewTimes(rt.lever, z, p);
    AddLeverGram(rt.lever, z, p, partial->blocks[cs].data(), partial->diagonal[cs].data());
    add_diagonal_of_elimination(cs, rt.Slot(cs));
  }
  for (const TargetTerm& term : rt.targets) {
    fold(term.q, term.qd, term.qd);
    SkewTimes(term.v, z, p);
    AddLeverGram(term.v, z, p, partial->blocks[term.camera].data(),
                 partial->diagonal[term.camera].data());
    add_diagonal_of_elimination(term.camera, rt.Slot(term.camera));
    if (cs < 0) continue;
    fold(term.q, rt.source_qd, term.qd);
    if (cs < term.camera) {
      AddSourceTargetCoupling(rt.lever, term.v, z,
                              partial->blocks[pattern.cross_block(term.residual)].data(), 6, 1);
    } else if (cs > term.camera) {
      AddSourceTargetCoupling(rt.lever, term.v, z,
                              partial->blocks[pattern.cross_block(term.residual)].data(), 1, 6);
    } else {
      // One image on both sides (the layouts skip such matches) couples it to itself: both
      // orders into its diagonal block (of which only the lower triangle is read).
      double* block = partial->blocks[cs].data();
      AddSourceTargetCoupling(rt.lever, term.v, z, block, 6, 1);
      AddSourceTargetCoupling(rt.lever, term.v, z, block, 1, 6);
    }
  }
}

// The rest of the elimination: the right-hand side (rhs += H_ct g_t / h̃; signs: rhs = -g), and
// the products the fold did not take (all of them when it did not apply). The group is ascending,
// so the blocks of (group[i], group[j > i]) come in one walk along group[i]'s couplings: k²/2
// pairs per ray time are the solve's bulk with long tracks, and a search per pair was a fifth of
// it.
[[gnu::always_inline]] inline void AddRestOfElimination(const RayTimeTerms& rt, double inverse,
                                                        bool folded,
                                                        const ReducedCameraPattern& pattern,
                                                        ReducedCameraSystem::Partial* partial) {
  const int num_variables = pattern.num_variables();
  const double scale = -inverse;
  for (int i = 0; i < rt.group_size; ++i) {
    const int ci = rt.group[i];
    double* elimination = partial->elimination[ci].data();
    for (int a = 0; a < 6; ++a) elimination[a] += rt.coupling[i][a] * (rt.g_t * inverse);
    if (!folded) AddScaledLowerOuter(partial->blocks[ci].data(), rt.coupling[i].data(), scale);
    if (folded && ci == rt.source_camera) continue;
    int n = pattern.first_neighbour(ci);
    for (int j = i + 1; j < rt.group_size; ++j) {
      if (folded && rt.group[j] == rt.source_camera) continue;
      while (pattern.neighbour(n) < rt.group[j]) ++n;
      AddScaledOuter(partial->blocks[num_variables + n].data(), rt.coupling[i].data(),
                     rt.coupling[j].data(), scale);
    }
  }
}

// One ray time linearized, reduced into the chunk's share and eliminated; its couplings, gradient
// and curvature kept for the back-substitution.
[[gnu::always_inline]] inline void LinearizeRayTime(const LinearizationInputs& in, int t,
                                                    RayTimeTerms* rt, ReducedCameraSystem* system,
                                                    ReducedCameraSystem::Partial* partial) {
  const ReducedCameraPattern& pattern = system->pattern();
  rt->group = pattern.group_begin(t);
  rt->group_size = static_cast<int>(pattern.group_end(t) - rt->group);
  rt->coupling = system->couplings(t);
  std::fill(rt->coupling, rt->coupling + rt->group_size, Row6{});
  if (pattern.residual_begin(t) == pattern.residual_end(t)) {  // no match left on it
    system->SetRayTime(t, 0.0, 0.0);
    return;
  }
  GatherResiduals(in, pattern, t, rt, partial);
  AddSourceTerms(in, t, rt, system, partial);
  const double inverse = 1.0 / (rt->h_tt + LmDamping(rt->h_tt, in.radius));
  const bool folded =
      rt->group_size == static_cast<int>(rt->targets.size()) + (rt->source_camera >= 0 ? 1 : 0);
  FoldElimination(*rt, inverse, folded, pattern, partial);
  AddRestOfElimination(*rt, inverse, folded, pattern, partial);
}

// One chunk of ray times' share of the system. Cloned for AVX2 (dispatched at load time): the
// compiler's own vectorization of the loops runs 4 doubles wide there instead of 2. No FMA in the
// clone, so nothing is contracted and the results are the default clone's to the bit. The
// helpers above are inlined into it (always_inline) so that they are compiled in both clones
// (measured: docs/scaling.md, "The LM's linearization kernel").
__attribute__((target_clones("avx2", "default"))) void LinearizeChunk(const LinearizationInputs& in,
                                                                      int chunk,
                                                                      ReducedCameraSystem* system) {
  const ReducedCameraPattern& pattern = system->pattern();
  ReducedCameraSystem::Partial& partial = system->partial(chunk);
  partial.Reset(pattern.num_blocks(), pattern.num_variables());
  RayTimeTerms rt;
  for (int t = pattern.chunk_begin(chunk); t < pattern.chunk_end(chunk); ++t) {
    LinearizeRayTime(in, t, &rt, system, &partial);
  }
}

// The pose priors: direct terms of each camera's diagonal block, its diagonal and its gradient.
void AddPriors(const RayTimeLmProblem& problem, const RayTimeLmPoint& point,
               ReducedCameraSystem* system) {
  const std::vector<PriorLinearization> priors = LinearizePriors(problem, point.world_from_cam);
  ReducedCameraSystem::Partial& total = system->total();
  for (size_t i = 0; i < priors.size(); ++i) {
    const int c = system->pattern().variable(static_cast<int>(i));
    if (c < 0) continue;
    const PriorLinearization& p = priors[i];
    const double centre_scale = p.centre_scale;
    const Eigen::Matrix3d ata = p.rotation_jacobian.transpose() * p.rotation_jacobian;
    const Eigen::Vector3d gradient = p.rotation_jacobian.transpose() * p.rotation_residual;
    Block6& block = total.blocks[c];
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) block[6 * a + b] += ata(a, b);
      block[6 * (3 + a) + 3 + a] += centre_scale * centre_scale;
      total.diagonal[c][a] += ata(a, a);
      total.diagonal[c][3 + a] += centre_scale * centre_scale;
      total.gradient[c][a] += gradient[a];
      total.gradient[c][3 + a] += centre_scale * p.centre_residual[a];
    }
  }
}

}  // namespace

void LinearizeRayTimeLm(const RayTimeLmProblem& problem, const RayTimeLmPoint& point,
                        const ScaledArctanLoss& loss, double radius, int num_threads,
                        ReducedCameraSystem* system) {
  const LinearizationInputs in{problem, point, loss, radius};
  ForEachFixedChunk(num_threads, [&](int chunk) { LinearizeChunk(in, chunk, system); });
  system->SumPartials();
  AddPriors(problem, point, system);
  system->Damp(radius);
}

}  // namespace raytime

// raytime's own 3D Gaussian Splatting renderer (issue 33 "Close the loop"; paper §4.5, Table 4):
// every trainer (gsplat, the Inria code, nerfstudio, OpenSplat) writes the standard 3DGS .ply, so
// raytime reads it and renders the held-out cameras itself, on the CPU, with one forward model for
// every trainer and pose source. The model is 3DGS's (Kerbl et al. 2023, §4 and its rasterizer):
// each Gaussian's 3D covariance R S Sᵀ Rᵀ carried to the image by the projection's Jacobian (EWA
// splatting) plus a 0.3 px² low-pass, its colour from its spherical harmonics up to the degree
// stored (evaluated in the direction from the camera centre), its opacity a sigmoid; per 16×16
// tile the Gaussians that reach it, front to back by depth, alpha-composited
// (α = min(max_alpha, o·exp(−½ dᵀ Σ⁻¹ d)), skipped below 1/255, stopping when the transmittance
// falls below 1e-4) over a background colour. What differs between the trainers' rasterizers (the
// α cap, the background, whether the principal point is used) is an option, so a model is
// rendered as its trainer renders it: SplatRenderOptionsOf(trainer).
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/geometry.h"

namespace raytime {

// Gaussians as the trainers store them (the .ply's fields): activations are applied by the
// renderer.
struct GaussianSplats {
  std::vector<Eigen::Vector3f> means;       // world, x y z
  std::vector<Eigen::Vector3f> log_scales;  // scale_0..2: the axes' standard deviations, log
  std::vector<Eigen::Vector4f> rotations;   // rot_0..3: quaternion w x y z, not normalized
  std::vector<float> opacity_logits;        // opacity: before the sigmoid
  // Spherical harmonics per Gaussian: (degree + 1)² coefficients × 3 colours, coefficient-major
  // (f_dc_0..2 are coefficient 0 of R, G, B; f_rest_k is channel k / (n − 1), coefficient
  // 1 + k % (n − 1): the trainers' channel-major layout, reordered on reading).
  std::vector<Eigen::VectorXf> sh;
  int sh_degree = 0;  // 0..3

  size_t size() const { return means.size(); }
};

// Gaussians with a field that is not finite (a mean, scale, rotation, opacity or SH coefficient):
// the renderer drops them, but a trainer that left any diverged or was broken, and its splats say
// nothing about the poses it was given (OpenSplat started from garbage points read from a double
// PLY and left over a tenth of the Gaussians NaN after 10 steps: issue 33's note). A log scale of
// −∞ is not counted: a Gaussian of size 0 (OpenSplat starts one where three neighbours coincide),
// which rasterizers draw as their 0.3 px² low-pass, as RenderGaussianSplats does.
size_t CountNonFiniteGaussians(const GaussianSplats& splats);

// Reads a 3DGS .ply (binary little-endian or ASCII; float or double properties; other properties
// such as normals ignored). InputError naming the file and what is wrong: not a PLY, no vertex
// element, a missing field, an SH count that is no (d + 1)² − 1 per channel, a truncated body.
GaussianSplats ReadGaussianSplatPly(const std::string& path);

// Writes `splats` as a binary little-endian 3DGS .ply (the fields ReadGaussianSplatPly reads, in
// the trainers' order and layout): for tests and for exports.
void WriteGaussianSplatPly(const GaussianSplats& splats, const std::string& path);

struct SplatRenderOptions {
  Eigen::Vector3f background = Eigen::Vector3f::Zero();  // RGB in [0, 1]
  // The cap on one Gaussian's α: 0.999 in gsplat and OpenSplat, 0.99 in the Inria code.
  float max_alpha = 0.999f;
  // Project with the principal point at the image centre, (w − 1) / 2, whatever the camera's:
  // the Inria code and OpenSplat's CPU rasterizer build their projection from the field of view
  // alone, so a model they trained is rendered so.
  bool centred_principal_point = false;
  // Draw each Gaussian only inside its axis-aligned box of ±3σ (the 2D covariance's diagonal) and
  // 2 px more, as OpenSplat's CPU rasterizer does; false: wherever its α reaches 1/255 in the tiles
  // its 3σ radius touches (gsplat, the Inria code, OpenSplat on a GPU).
  bool clip_to_box = false;
  // Gaussians nearer than this to the camera plane are not drawn (the rasterizers' near plane;
  // gsplat and OpenSplat: 0.01), length units of the scene.
  double near = 0.01;
  int num_threads =
      0;  // tiles rendered in parallel; 0: all cores (the result does not depend on it)
};

// Renders `splats` seen by a pinhole camera (`camera`'s fx, fy, cx, cy in the OpenCV convention,
// pixel (i, j) centred at (i, j), which is the Inria rasterizer's convention with a COLMAP model's
// cx − 0.5; its distortion is not applied: render undistorted views) at `world_from_cam` (camera
// axes x right, y down, z forward). Returns CV_32FC3 BGR in [0, 1] (channels ordered as cv::imread
// gives a photo, so Psnr and Ssim compare them directly), `camera.width` × `camera.height`.
// How `trainer` (kSplatTrainers) rasterizes: gsplat black background, α cap 0.999, principal point
// used; inria black, 0.99, centred; opensplat nerfstudio's fixed background (0.6130, 0.0101,
// 0.3984), 0.999, centred, clipped to the box (its CPU path; its CUDA path is gsplat's);
// nerfstudio (splatfacto: gsplat) as gsplat. Unknown names get the defaults.
SplatRenderOptions SplatRenderOptionsOf(const std::string& trainer);

cv::Mat RenderGaussianSplats(const GaussianSplats& splats, const CameraIntrinsics& camera,
                             const Rigid3& world_from_cam,
                             const SplatRenderOptions& options = SplatRenderOptions());

// The colour of Gaussian `sh` (coefficient-major as in GaussianSplats, degree `degree`) seen along
// the unit direction `direction` (from the camera centre to the Gaussian), before the +0.5 offset
// and the clamp at 0: the real spherical harmonics basis of the 3DGS code.
Eigen::Vector3f EvaluateSphericalHarmonics(const Eigen::VectorXf& sh, int degree,
                                           const Eigen::Vector3f& direction);

}  // namespace raytime

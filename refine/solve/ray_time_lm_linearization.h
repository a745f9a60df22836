// The ray-time LM's linearization (ray_time_lm_solver.h): the problem at a point, linearized and
// reduced into the reduced camera system (reduced_camera_system.h) with each ray time eliminated
// as its residuals are linearized, so no Jacobian is stored.
#pragma once

#include "refine/solve/arctan_loss.h"
#include "refine/solve/ray_time_lm_kernel.h"
#include "refine/solve/reduced_camera_system.h"

namespace raytime {

// Fills `system` at `point` for trust-region radius μ (the ray times are eliminated with their
// damping h_tt + D_t/μ): every fixed chunk of ray times linearized into its share (on at most
// num_threads threads), the shares summed in chunk order, the pose priors added and the cameras'
// damping set. The residuals are weighted by the loss's ρ' as Ceres' corrector does for a loss
// with ρ'' < 0 (J and r scaled by sqrt(w ρ')).
void LinearizeRayTimeLm(const RayTimeLmProblem& problem, const RayTimeLmPoint& point,
                        const ScaledArctanLoss& loss, double radius, int num_threads,
                        ReducedCameraSystem* system);

}  // namespace raytime

#include "refine/refine_options.h"

#include <thread>

namespace raytime {

std::vector<double> RefineOptions::StageScales() const {
  std::vector<double> scales = gnc_scales;
  if (scales.empty() || scales.back() != loss_scale_px2) scales.push_back(loss_scale_px2);
  return scales;
}

int RefineOptions::Threads() const {
  if (num_threads > 0) return num_threads;
  return std::max(1u, std::thread::hardware_concurrency());
}

}  // namespace raytime

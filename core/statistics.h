// Order statistics shared by the evaluation and the refiner's diagnostics.
#pragma once

#include <algorithm>
#include <vector>

namespace raytime {

// Median: the mean of the two middle values for an even count; `if_empty` when there are none.
inline double Median(std::vector<double> values, double if_empty) {
  if (values.empty()) return if_empty;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  const double upper = values[mid];
  if (values.size() % 2 == 1) return upper;
  const double lower = *std::max_element(values.begin(), values.begin() + mid);
  return 0.5 * (lower + upper);
}

}  // namespace raytime

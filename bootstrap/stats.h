// Small order statistics shared by the bootstrap estimators and their summaries.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace raytime {

// Median of the finite values (upper median for even counts), 0 when there are none.
inline double FiniteMedian(std::vector<double> values) {
  values.erase(
      std::remove_if(values.begin(), values.end(), [](double x) { return !std::isfinite(x); }),
      values.end());
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

// Mean of the finite values, 0 when there are none.
inline double FiniteMean(const std::vector<double>& values) {
  double sum = 0.0;
  int count = 0;
  for (double x : values) {
    if (std::isfinite(x)) {
      sum += x;
      ++count;
    }
  }
  return count ? sum / count : 0.0;
}

}  // namespace raytime

// Order statistics shared by the stages. Two median conventions are in use, and each caller keeps
// the one its results were measured with: Median averages the two middle values of an even count
// (pose errors, campaign reports, the pair-consistency residuals, the perturbation protocol's
// scene distance); UpperMedian takes the upper one, always one of the samples (the bootstrap's
// estimators, the refiner's ray-time initialization and guardrails).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

namespace raytime {

// The mean of the two middle values for an even count; `if_empty` when there are none.
inline double Median(std::vector<double> values, double if_empty) {
  if (values.empty()) return if_empty;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  const double upper = values[mid];
  if (values.size() % 2 == 1) return upper;
  const double lower = *std::max_element(values.begin(), values.begin() + mid);
  return 0.5 * (lower + upper);
}

// The upper of the two middle values for an even count; `if_empty` when there are none.
inline double UpperMedian(std::vector<double> values, double if_empty) {
  if (values.empty()) return if_empty;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

// `values` without NaN and infinities.
inline std::vector<double> FiniteValues(std::vector<double> values) {
  values.erase(
      std::remove_if(values.begin(), values.end(), [](double x) { return !std::isfinite(x); }),
      values.end());
  return values;
}

// UpperMedian of the finite values, 0 when there are none.
inline double FiniteUpperMedian(std::vector<double> values) {
  return UpperMedian(FiniteValues(std::move(values)), 0.0);
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

// The nearest-rank q-quantile (0 < q <= 1): the ceil(q n)-th smallest value; if_empty for none.
inline double NearestRankQuantile(std::vector<double> values, double q, double if_empty) {
  if (values.empty()) return if_empty;
  const double rank = std::ceil(q * static_cast<double>(values.size()));
  const size_t index = static_cast<size_t>(std::clamp(rank, 1.0, double(values.size()))) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index),
                   values.end());
  return values[index];
}

}  // namespace raytime

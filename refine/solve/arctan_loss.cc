#include "refine/solve/arctan_loss.h"

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <cmath>

#if defined(__x86_64__)
// glibc's vector atan for AVX2 (libmvec, since 2.35).
extern "C" __attribute__((target("avx2"))) __m256d _ZGVdN4v_atan(__m256d x);
#endif

namespace raytime {

#if defined(__x86_64__)
namespace {

__attribute__((target("avx2"))) double SumOfArctansAvx2(const double* s, int n, double scale) {
  const __m256d a = _mm256_set1_pd(scale);
  __m256d sum = _mm256_setzero_pd();
  int k = 0;
  for (; k + 4 <= n; k += 4) {
    sum = _mm256_add_pd(sum, _ZGVdN4v_atan(_mm256_div_pd(_mm256_loadu_pd(s + k), a)));
  }
  if (k < n) {
    double rest[4] = {0.0, 0.0, 0.0, 0.0};  // atan(0) = 0
    for (int j = 0; k + j < n; ++j) rest[j] = s[k + j];
    sum = _mm256_add_pd(sum, _ZGVdN4v_atan(_mm256_div_pd(_mm256_loadu_pd(rest), a)));
  }
  double lanes[4];
  _mm256_storeu_pd(lanes, sum);
  return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
}

}  // namespace
#endif

double SumOfArctans(const double* s, int n, double scale) {
#if defined(__x86_64__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2) return SumOfArctansAvx2(s, n, scale);
#endif
  double sum = 0.0;
  for (int k = 0; k < n; ++k) sum += std::atan(s[k] / scale);
  return sum;
}

}  // namespace raytime

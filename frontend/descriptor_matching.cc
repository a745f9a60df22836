#include "frontend/descriptor_matching.h"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <stdexcept>

#include "core/error.h"
#include "core/options.h"

namespace raytime {
namespace {

constexpr float kNoSimilarity = -std::numeric_limits<float>::infinity();

// Running top-2 of one query.
struct Top2 {
  float best = kNoSimilarity;
  float second = kNoSimilarity;
  int index = -1;

  // Merges a partial top-2 computed over other references; ties go to the smaller index so that
  // the result does not depend on the order in which partial results arrive.
  void Merge(float other_best, float other_second, int other_index) {
    if (other_index < 0) return;
    if (other_best > best || (other_best == best && other_index < index)) {
      second = std::max(best, other_second);
      best = other_best;
      index = other_index;
    } else {
      second = std::max(second, other_best);
    }
  }
  // Adds one reference; references must arrive in increasing index order.
  void Add(float value, int value_index) {
    if (value > best) {
      second = best;
      best = value;
      index = value_index;
    } else if (value > second) {
      second = value;
    }
  }
};

void ToNeighborList(const std::vector<Top2>& top, NeighborList* list) {
  list->index.resize(top.size());
  list->best.resize(top.size());
  list->second.resize(top.size());
  for (size_t i = 0; i < top.size(); ++i) {
    list->index[i] = top[i].index;
    list->best[i] = top[i].best;
    list->second[i] = top[i].second;
  }
}

// ---- Portable kernel: cv::gemm on blocks of rows, scalar scan. ----

void FindNeighborsGemm(const FloatDescriptors& a, const FloatDescriptors& b,
                       std::vector<Top2>* rows, std::vector<Top2>* cols) {
  // 256 rows x 8192 columns of float is 8 MB: big enough for sgemm to run at speed, small
  // enough that the block is scanned while still in the last-level cache.
  constexpr int kBlockRows = 256;
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(b.rows());
  const int dim = static_cast<int>(a.cols());
  const cv::Mat b_mat(m, dim, CV_32F, const_cast<float*>(b.data()));
  cv::Mat block;
  for (int r0 = 0; r0 < n; r0 += kBlockRows) {
    const int count = std::min(kBlockRows, n - r0);
    const cv::Mat a_mat(count, dim, CV_32F, const_cast<float*>(a.data() + size_t(r0) * dim));
    cv::gemm(a_mat, b_mat, 1.0, cv::noArray(), 0.0, block, cv::GEMM_2_T);
    for (int r = 0; r < count; ++r) {
      const float* row = block.ptr<float>(r);
      Top2& top = (*rows)[r0 + r];
      for (int j = 0; j < m; ++j) {
        top.Add(row[j], j);
        (*cols)[j].Add(row[j], r0 + r);
      }
    }
  }
}

// ---- AVX2/FMA kernel. ----
//
// B is packed into panels of 16 columns (dim x 16 floats each, zero-padded past m). A 6 x 16 tile
// of dot products lives in 12 ymm accumulators for the whole dim loop (two 8-wide loads of B and
// six broadcasts of A per step: the classic register-blocked GEMM micro-kernel). Panels are
// visited in blocks that fit the L2 cache; each 6-row strip of a block is scanned for the top-2
// of its rows and columns while it is still in L1, so the n x m matrix is never stored.

constexpr int kPanelWidth = 16;
constexpr int kTileRows = 6;
constexpr int kBlockPanels = 64;  // 1024 columns: 512 KB of packed B at dim 128

__attribute__((target("avx2,fma"))) void MicroKernel6x16(const float* a, int dim,
                                                         const float* panel, float* out, int ld) {
  __m256 c00 = _mm256_setzero_ps(), c01 = _mm256_setzero_ps();
  __m256 c10 = _mm256_setzero_ps(), c11 = _mm256_setzero_ps();
  __m256 c20 = _mm256_setzero_ps(), c21 = _mm256_setzero_ps();
  __m256 c30 = _mm256_setzero_ps(), c31 = _mm256_setzero_ps();
  __m256 c40 = _mm256_setzero_ps(), c41 = _mm256_setzero_ps();
  __m256 c50 = _mm256_setzero_ps(), c51 = _mm256_setzero_ps();
  for (int k = 0; k < dim; ++k) {
    const __m256 b0 = _mm256_loadu_ps(panel + kPanelWidth * k);
    const __m256 b1 = _mm256_loadu_ps(panel + kPanelWidth * k + 8);
    __m256 x = _mm256_broadcast_ss(a + k);
    c00 = _mm256_fmadd_ps(x, b0, c00);
    c01 = _mm256_fmadd_ps(x, b1, c01);
    x = _mm256_broadcast_ss(a + dim + k);
    c10 = _mm256_fmadd_ps(x, b0, c10);
    c11 = _mm256_fmadd_ps(x, b1, c11);
    x = _mm256_broadcast_ss(a + 2 * dim + k);
    c20 = _mm256_fmadd_ps(x, b0, c20);
    c21 = _mm256_fmadd_ps(x, b1, c21);
    x = _mm256_broadcast_ss(a + 3 * dim + k);
    c30 = _mm256_fmadd_ps(x, b0, c30);
    c31 = _mm256_fmadd_ps(x, b1, c31);
    x = _mm256_broadcast_ss(a + 4 * dim + k);
    c40 = _mm256_fmadd_ps(x, b0, c40);
    c41 = _mm256_fmadd_ps(x, b1, c41);
    x = _mm256_broadcast_ss(a + 5 * dim + k);
    c50 = _mm256_fmadd_ps(x, b0, c50);
    c51 = _mm256_fmadd_ps(x, b1, c51);
  }
  _mm256_storeu_ps(out, c00);
  _mm256_storeu_ps(out + 8, c01);
  _mm256_storeu_ps(out + ld, c10);
  _mm256_storeu_ps(out + ld + 8, c11);
  _mm256_storeu_ps(out + 2 * ld, c20);
  _mm256_storeu_ps(out + 2 * ld + 8, c21);
  _mm256_storeu_ps(out + 3 * ld, c30);
  _mm256_storeu_ps(out + 3 * ld + 8, c31);
  _mm256_storeu_ps(out + 4 * ld, c40);
  _mm256_storeu_ps(out + 4 * ld + 8, c41);
  _mm256_storeu_ps(out + 5 * ld, c50);
  _mm256_storeu_ps(out + 5 * ld + 8, c51);
}

// One 8-lane top-2 step: lanes where `v` beats `best` shift best into second.
__attribute__((target("avx2,fma"))) inline void LaneTop2(__m256 v, __m256 v_index, __m256* best,
                                                         __m256* second, __m256* index) {
  const __m256 greater = _mm256_cmp_ps(v, *best, _CMP_GT_OQ);
  *second = _mm256_blendv_ps(_mm256_max_ps(*second, v), *best, greater);
  *best = _mm256_blendv_ps(*best, v, greater);
  *index = _mm256_blendv_ps(*index, v_index, greater);
}

// Scans a strip of `rows_valid` rows x `width` columns (row stride `width`) whose first entry is
// the dot product of query row `row0` with reference column `col0`. Indices travel through the
// blends as the bit patterns of int32 lanes.
__attribute__((target("avx2,fma"))) void ScanStrip(const float* strip, int rows_valid, int width,
                                                   int row0, int col0, Top2* rows, float* col_best,
                                                   float* col_second, int* col_index) {
  for (int r = 0; r < rows_valid; ++r) {
    const float* values = strip + size_t(r) * width;
    __m256 best = _mm256_set1_ps(kNoSimilarity), second = best;
    __m256 index = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
    __m256i column = _mm256_setr_epi32(col0, col0 + 1, col0 + 2, col0 + 3, col0 + 4, col0 + 5,
                                       col0 + 6, col0 + 7);
    const __m256i step = _mm256_set1_epi32(8);
    for (int c = 0; c < width; c += 8) {
      LaneTop2(_mm256_loadu_ps(values + c), _mm256_castsi256_ps(column), &best, &second, &index);
      column = _mm256_add_epi32(column, step);
    }
    alignas(32) float lane_best[8], lane_second[8];
    alignas(32) int lane_index[8];
    _mm256_store_ps(lane_best, best);
    _mm256_store_ps(lane_second, second);
    _mm256_store_si256(reinterpret_cast<__m256i*>(lane_index), _mm256_castps_si256(index));
    Top2& top = rows[row0 + r];
    for (int lane = 0; lane < 8; ++lane)
      top.Merge(lane_best[lane], lane_second[lane], lane_index[lane]);
  }
  for (int c = 0; c < width; c += 8) {
    __m256 best = _mm256_loadu_ps(col_best + col0 + c);
    __m256 second = _mm256_loadu_ps(col_second + col0 + c);
    __m256 index = _mm256_castsi256_ps(
        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(col_index + col0 + c)));
    for (int r = 0; r < rows_valid; ++r) {
      LaneTop2(_mm256_loadu_ps(strip + size_t(r) * width + c),
               _mm256_castsi256_ps(_mm256_set1_epi32(row0 + r)), &best, &second, &index);
    }
    _mm256_storeu_ps(col_best + col0 + c, best);
    _mm256_storeu_ps(col_second + col0 + c, second);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(col_index + col0 + c),
                        _mm256_castps_si256(index));
  }
}

// Not itself compiled for AVX2: only the micro-kernel and the scan are, so no Eigen code is
// generated with instructions the rest of the program does not assume.
void FindNeighborsAvx2(const FloatDescriptors& a, const FloatDescriptors& b,
                       std::vector<Top2>* rows, std::vector<Top2>* cols) {
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(b.rows());
  const int dim = static_cast<int>(a.cols());
  const int num_panels = (m + kPanelWidth - 1) / kPanelWidth;
  const int m_padded = num_panels * kPanelWidth;
  std::vector<float> packed(size_t(m_padded) * dim, 0.0f);
  for (int j = 0; j < m; ++j) {
    float* panel = packed.data() + size_t(j / kPanelWidth) * dim * kPanelWidth;
    for (int k = 0; k < dim; ++k) panel[k * kPanelWidth + j % kPanelWidth] = b(j, k);
  }
  const int n_padded = (n + kTileRows - 1) / kTileRows * kTileRows;
  std::vector<float> a_padded(size_t(n_padded) * dim, 0.0f);
  std::copy(a.data(), a.data() + size_t(n) * dim, a_padded.begin());

  std::vector<float> col_best(m_padded, kNoSimilarity), col_second(m_padded, kNoSimilarity);
  std::vector<int> col_index(m_padded, -1);
  std::vector<float> strip(size_t(kTileRows) * kBlockPanels * kPanelWidth);
  for (int p0 = 0; p0 < num_panels; p0 += kBlockPanels) {
    const int p1 = std::min(num_panels, p0 + kBlockPanels);
    const int width = (p1 - p0) * kPanelWidth;
    const int col0 = p0 * kPanelWidth;
    for (int r0 = 0; r0 < n_padded; r0 += kTileRows) {
      for (int p = p0; p < p1; ++p) {
        MicroKernel6x16(a_padded.data() + size_t(r0) * dim, dim,
                        packed.data() + size_t(p) * dim * kPanelWidth,
                        strip.data() + (p - p0) * kPanelWidth, width);
      }
      // Padding columns must never win.
      for (int r = 0; r < kTileRows; ++r) {
        for (int c = std::max(0, m - col0); c < width; ++c)
          strip[size_t(r) * width + c] = kNoSimilarity;
      }
      ScanStrip(strip.data(), std::min(kTileRows, n - r0), width, r0, col0, rows->data(),
                col_best.data(), col_second.data(), col_index.data());
    }
  }
  for (int j = 0; j < m; ++j) {
    (*cols)[j] = Top2{col_best[j], col_second[j], col_index[j]};
  }
}

// ---- Guided matching scans. ----
//
// Candidate (i, j) when the Sampson distance of x2_j to x1_i under F is below the threshold:
// (l_i . x2_j)^2 < max_error^2 (|l_i|_12^2 + |F^T x2_j|_12^2) with l_i = F x1_i. About 1 % of
// the pairs pass (a band of ~10 px across a 1500 px image), so the screening of all n x m pairs
// dominates; the dot products are computed for the candidates only.
struct GuidedInput {
  const float* a = nullptr;
  const float* b = nullptr;
  int n = 0, m = 0, dim = 0;
  float max_error_sq = 0;
  std::vector<float> u2, v2, g2;  // padded to a multiple of 8 with NaN
  std::vector<float> lines;       // n x 3
};

void GuidedScanPortable(const GuidedInput& in, Top2* rows, Top2* cols) {
  for (int i = 0; i < in.n; ++i) {
    const float l0 = in.lines[3 * i], l1 = in.lines[3 * i + 1], l2 = in.lines[3 * i + 2];
    const float bound = in.max_error_sq * (l0 * l0 + l1 * l1);
    const float* ai = in.a + size_t(i) * in.dim;
    for (int j = 0; j < in.m; ++j) {
      const float r = l0 * in.u2[j] + l1 * in.v2[j] + l2;
      if (!(r * r < bound + in.max_error_sq * in.g2[j])) continue;
      const float* bj = in.b + size_t(j) * in.dim;
      float dot = 0.0f;
      for (int k = 0; k < in.dim; ++k) dot += ai[k] * bj[k];
      rows[i].Add(dot, j);
      cols[j].Add(dot, i);
    }
  }
}

__attribute__((target("avx2,fma"))) float DotAvx2(const float* x, const float* y, int dim) {
  __m256 sum = _mm256_setzero_ps();
  int k = 0;
  for (; k + 8 <= dim; k += 8) {
    sum = _mm256_fmadd_ps(_mm256_loadu_ps(x + k), _mm256_loadu_ps(y + k), sum);
  }
  __m128 half = _mm_add_ps(_mm256_castps256_ps128(sum), _mm256_extractf128_ps(sum, 1));
  half = _mm_add_ps(half, _mm_movehl_ps(half, half));
  half = _mm_add_ss(half, _mm_shuffle_ps(half, half, 1));
  float dot = _mm_cvtss_f32(half);
  for (; k < dim; ++k) dot += x[k] * y[k];
  return dot;
}

__attribute__((target("avx2,fma"))) void GuidedScanAvx2(const GuidedInput& in, Top2* rows,
                                                        Top2* cols) {
  const int m_padded = static_cast<int>(in.u2.size());
  const __m256 max_error_sq = _mm256_set1_ps(in.max_error_sq);
  for (int i = 0; i < in.n; ++i) {
    const float l0 = in.lines[3 * i], l1 = in.lines[3 * i + 1], l2 = in.lines[3 * i + 2];
    const __m256 L0 = _mm256_set1_ps(l0), L1 = _mm256_set1_ps(l1), L2 = _mm256_set1_ps(l2);
    const __m256 bound = _mm256_set1_ps(in.max_error_sq * (l0 * l0 + l1 * l1));
    const float* ai = in.a + size_t(i) * in.dim;
    for (int j0 = 0; j0 < m_padded; j0 += 8) {
      const __m256 r = _mm256_fmadd_ps(L0, _mm256_loadu_ps(in.u2.data() + j0),
                                       _mm256_fmadd_ps(L1, _mm256_loadu_ps(in.v2.data() + j0), L2));
      const __m256 limit = _mm256_fmadd_ps(max_error_sq, _mm256_loadu_ps(in.g2.data() + j0), bound);
      unsigned mask = static_cast<unsigned>(
          _mm256_movemask_ps(_mm256_cmp_ps(_mm256_mul_ps(r, r), limit, _CMP_LT_OQ)));
      while (mask) {
        const int j = j0 + __builtin_ctz(mask);
        mask &= mask - 1;
        const float dot = DotAvx2(ai, in.b + size_t(j) * in.dim, in.dim);
        rows[i].Add(dot, j);
        cols[j].Add(dot, i);
      }
    }
  }
}

float Distance(float similarity) { return std::sqrt(std::max(0.0f, 2.0f - 2.0f * similarity)); }

bool Passes(float best, float second, double max_ratio, double max_distance) {
  const float distance = Distance(best);
  return distance < max_distance && distance < max_ratio * Distance(std::max(second, 0.0f));
}

}  // namespace

MatchKernel ParseMatchKernel(const std::string& name, const std::string& what) {
  if (name == "auto") return MatchKernel::kAuto;
  if (name == "avx2") return MatchKernel::kAvx2;
  if (name == "gemm") return MatchKernel::kGemm;
  throw InputError(UnknownKeyMessage(what, name, {"auto", "avx2", "gemm"}, "kernel"));
}

const char* MatchKernelName(MatchKernel kernel) {
  switch (kernel) {
    case MatchKernel::kAuto:
      return "auto";
    case MatchKernel::kAvx2:
      return "avx2";
    case MatchKernel::kGemm:
      return "gemm";
  }
  return "?";
}

bool CpuHasAvx2Fma() { return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"); }

MatchKernel ResolveMatchKernel(MatchKernel kernel) {
  if (kernel == MatchKernel::kAuto)
    return CpuHasAvx2Fma() ? MatchKernel::kAvx2 : MatchKernel::kGemm;
  if (kernel == MatchKernel::kAvx2 && !CpuHasAvx2Fma()) {
    throw std::runtime_error("matching kernel 'avx2' requested but this CPU lacks AVX2/FMA");
  }
  return kernel;
}

FloatDescriptors NormalizeDescriptors(const ByteDescriptors& descriptors) {
  FloatDescriptors out = descriptors.cast<float>();
  for (Eigen::Index i = 0; i < out.rows(); ++i) {
    const float norm = out.row(i).norm();
    if (norm > 0) out.row(i) /= norm;
  }
  return out;
}

void FindNeighbors(const FloatDescriptors& a, const FloatDescriptors& b, MatchKernel kernel,
                   NeighborList* a_to_b, NeighborList* b_to_a) {
  std::vector<Top2> rows(a.rows()), cols(b.rows());
  if (a.rows() > 0 && b.rows() > 0) {
    if (a.cols() != b.cols()) {
      throw std::invalid_argument("FindNeighbors: descriptor lengths differ (" +
                                  std::to_string(a.cols()) + " vs " + std::to_string(b.cols()) +
                                  ")");
    }
    if (ResolveMatchKernel(kernel) == MatchKernel::kAvx2) {
      FindNeighborsAvx2(a, b, &rows, &cols);
    } else {
      FindNeighborsGemm(a, b, &rows, &cols);
    }
  }
  ToNeighborList(rows, a_to_b);
  ToNeighborList(cols, b_to_a);
}

MatchList RatioTestMatches(const NeighborList& a_to_b, const NeighborList& b_to_a, double max_ratio,
                           double max_distance, bool mutual) {
  std::vector<std::pair<uint32_t, uint32_t>> kept;
  for (size_t i = 0; i < a_to_b.index.size(); ++i) {
    const int j = a_to_b.index[i];
    if (j < 0 || !Passes(a_to_b.best[i], a_to_b.second[i], max_ratio, max_distance)) continue;
    if (mutual && (b_to_a.index[j] != static_cast<int>(i) ||
                   !Passes(b_to_a.best[j], b_to_a.second[j], max_ratio, max_distance))) {
      continue;
    }
    kept.emplace_back(static_cast<uint32_t>(i), static_cast<uint32_t>(j));
  }
  MatchList matches(kept.size(), 2);
  for (size_t k = 0; k < kept.size(); ++k) {
    matches(k, 0) = kept[k].first;
    matches(k, 1) = kept[k].second;
  }
  return matches;
}

MatchList GuidedMatches(const FloatDescriptors& a, const FloatDescriptors& b,
                        const Eigen::Matrix<double, Eigen::Dynamic, 2>& x1,
                        const Eigen::Matrix<double, Eigen::Dynamic, 2>& x2,
                        const Eigen::Matrix3d& F, double max_error_px, double max_ratio,
                        double max_distance, bool mutual, MatchKernel kernel) {
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(b.rows());
  const int dim = static_cast<int>(a.cols());
  if (x1.rows() != n || x2.rows() != m) {
    throw std::invalid_argument("GuidedMatches: keypoint and descriptor counts differ");
  }
  if (n == 0 || m == 0) return MatchList(0, 2);
  if (b.cols() != dim) throw std::invalid_argument("GuidedMatches: descriptor lengths differ");
  // The Sampson distance is invariant to the scale of F; unit norm keeps the float screening
  // well inside float range.
  const Eigen::Matrix3d Fn = F / F.norm();
  GuidedInput in;
  in.a = a.data();
  in.b = b.data();
  in.n = n;
  in.m = m;
  in.dim = dim;
  in.max_error_sq = static_cast<float>(max_error_px * max_error_px);
  // Per reference: position and the squared norm of the first two entries of F^T x2; padding
  // entries are NaN, which fail every comparison.
  const int m_padded = (m + 7) / 8 * 8;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  in.u2.assign(m_padded, nan);
  in.v2.assign(m_padded, nan);
  in.g2.assign(m_padded, nan);
  for (int j = 0; j < m; ++j) {
    const Eigen::Vector3d x(x2(j, 0), x2(j, 1), 1.0);
    const Eigen::Vector3d g = Fn.transpose() * x;
    in.u2[j] = static_cast<float>(x.x());
    in.v2[j] = static_cast<float>(x.y());
    in.g2[j] = static_cast<float>(g.x() * g.x() + g.y() * g.y());
  }
  in.lines.resize(size_t(n) * 3);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d l = Fn * Eigen::Vector3d(x1(i, 0), x1(i, 1), 1.0);
    for (int c = 0; c < 3; ++c) in.lines[3 * i + c] = static_cast<float>(l(c));
  }
  std::vector<Top2> rows(n), cols(m);
  if (ResolveMatchKernel(kernel) == MatchKernel::kAvx2) {
    GuidedScanAvx2(in, rows.data(), cols.data());
  } else {
    GuidedScanPortable(in, rows.data(), cols.data());
  }
  NeighborList a_to_b, b_to_a;
  ToNeighborList(rows, &a_to_b);
  ToNeighborList(cols, &b_to_a);
  return RatioTestMatches(a_to_b, b_to_a, max_ratio, max_distance, mutual);
}

}  // namespace raytime

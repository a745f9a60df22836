#include "frontend/descriptor_matching.h"

#include <cpuid.h>
#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/core.hpp>
#include <stdexcept>
#include <type_traits>

#include "core/error.h"

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

// The descriptors as the kernels read them: the quantized values as floats (integers, so every
// dot product of two rows is an integer below 128 * 255^2 < 2^24 and float arithmetic computes it
// exactly in any order), and each row's inverse norm.
struct Descriptors {
  int rows = 0;
  int dim = 0;
  std::vector<float> storage;  // rows x dim, row-major
  std::vector<float> inverse_norm;
  const float* values() const { return storage.data(); }
};

Descriptors Prepare(const ByteDescriptors& bytes) {
  Descriptors d;
  d.rows = static_cast<int>(bytes.rows());
  d.dim = static_cast<int>(bytes.cols());
  d.storage.resize(size_t(d.rows) * d.dim);
  d.inverse_norm.resize(d.rows);
  for (int i = 0; i < d.rows; ++i) {
    int64_t sum = 0;
    for (int k = 0; k < d.dim; ++k) {
      const int v = bytes(i, k);
      d.storage[size_t(i) * d.dim + k] = static_cast<float>(v);
      sum += v * v;
    }
    d.inverse_norm[i] =
        sum > 0 ? static_cast<float>(1.0 / std::sqrt(static_cast<double>(sum))) : 0.0f;
  }
  return d;
}

// The cosine similarity from the exact integer dot product: the same expression (two float
// products in this order) in every kernel, so all kernels agree to the bit.
inline float Similarity(float dot, float inverse_norm_a, float inverse_norm_b) {
  return dot * inverse_norm_a * inverse_norm_b;
}

// ---- Portable kernel: cv::gemm on blocks of rows, scalar scan. ----

void FindNeighborsGemm(const Descriptors& a, const Descriptors& b, std::vector<Top2>* rows,
                       std::vector<Top2>* cols) {
  // 256 rows x 8192 columns of float is 8 MB: big enough for sgemm to run at speed, small
  // enough that the block is scanned while still in the last-level cache.
  constexpr int kBlockRows = 256;
  const int n = a.rows, m = b.rows, dim = a.dim;
  const cv::Mat b_mat(m, dim, CV_32F, const_cast<float*>(b.values()));
  cv::Mat block;
  for (int r0 = 0; r0 < n; r0 += kBlockRows) {
    const int count = std::min(kBlockRows, n - r0);
    const cv::Mat a_mat(count, dim, CV_32F, const_cast<float*>(a.values() + size_t(r0) * dim));
    cv::gemm(a_mat, b_mat, 1.0, cv::noArray(), 0.0, block, cv::GEMM_2_T);
    for (int r = 0; r < count; ++r) {
      const float* row = block.ptr<float>(r);
      Top2& top = (*rows)[r0 + r];
      const float inverse_norm = a.inverse_norm[r0 + r];
      for (int j = 0; j < m; ++j) {
        const float similarity = Similarity(row[j], inverse_norm, b.inverse_norm[j]);
        top.Add(similarity, j);
        (*cols)[j].Add(similarity, r0 + r);
      }
    }
  }
}

// ---- Tiled kernels: AVX2/FMA on floats, VNNI on bytes. ----
//
// B is packed into panels of 16 columns (zero-padded past m). A 6 x 16 tile of dot products lives
// in 12 ymm accumulators for the whole dim loop (two loads of B and six broadcasts of A per step:
// the classic register-blocked GEMM micro-kernel). Panels are visited in blocks that fit the L2
// cache; each 6-row strip of a block is scaled to similarities and scanned for the top-2 of its
// rows and columns while it is still in L1, so the n x m matrix is never stored.
//
// The float tile takes one dimension per step (8 products per FMA). The byte tile takes four:
// vpdpbusd multiplies 32 unsigned bytes of A by 32 signed bytes of B and sums them in fours into
// 8 int32 lanes, in one instruction. B's bytes are stored as b - 128 (signed), so the tile
// computes a·b - 128·Σa and the scan adds 128·Σa back. Both tiles compute the integer dot
// products exactly, so they give the same similarities. Measured (bench/matcher_bench.cc,
// fountain-P11 0000 x 0001, 8192 x 8192, 1 thread, AMD EPYC with AVX-VNNI): byte tile 0.109 s,
// float tile 0.207 s, a 16-bit tile (vpdpwssd, 16 products per instruction) 0.174 s.

constexpr int kPanelWidth = 16;
constexpr int kTileRows = 6;
constexpr int kBlockPanels = 64;  // 1024 columns: 512 KB of packed float B at dim 128

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

inline int32_t LoadQuad(const uint8_t* p) {
  int32_t v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}

// The byte tile, once per instruction set that has vpdpbusd on ymm registers: AVX-VNNI (VEX) and
// AVX512-VNNI with AVX512-VL (EVEX). `dim` is a multiple of 4. The products of the signed bytes
// fit in 16 bits and their sums of four in 32 (no saturation: vpdpbusd, not vpdpbusds).
#define RAYTIME_DEFINE_VNNI_TILE(name, isa, dpbusd)                                            \
  __attribute__((target(isa))) void name(const uint8_t* a, int dim, const int8_t* panel,       \
                                         float* out, int ld) {                                 \
    __m256i c00 = _mm256_setzero_si256(), c01 = _mm256_setzero_si256();                        \
    __m256i c10 = _mm256_setzero_si256(), c11 = _mm256_setzero_si256();                        \
    __m256i c20 = _mm256_setzero_si256(), c21 = _mm256_setzero_si256();                        \
    __m256i c30 = _mm256_setzero_si256(), c31 = _mm256_setzero_si256();                        \
    __m256i c40 = _mm256_setzero_si256(), c41 = _mm256_setzero_si256();                        \
    __m256i c50 = _mm256_setzero_si256(), c51 = _mm256_setzero_si256();                        \
    for (int k = 0; k < dim; k += 4) {                                                         \
      const __m256i b0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(panel + 16 * k)); \
      const __m256i b1 =                                                                       \
          _mm256_loadu_si256(reinterpret_cast<const __m256i*>(panel + 16 * k + 32));           \
      __m256i x = _mm256_set1_epi32(LoadQuad(a + k));                                          \
      c00 = dpbusd(c00, x, b0);                                                                \
      c01 = dpbusd(c01, x, b1);                                                                \
      x = _mm256_set1_epi32(LoadQuad(a + dim + k));                                            \
      c10 = dpbusd(c10, x, b0);                                                                \
      c11 = dpbusd(c11, x, b1);                                                                \
      x = _mm256_set1_epi32(LoadQuad(a + 2 * dim + k));                                        \
      c20 = dpbusd(c20, x, b0);                                                                \
      c21 = dpbusd(c21, x, b1);                                                                \
      x = _mm256_set1_epi32(LoadQuad(a + 3 * dim + k));                                        \
      c30 = dpbusd(c30, x, b0);                                                                \
      c31 = dpbusd(c31, x, b1);                                                                \
      x = _mm256_set1_epi32(LoadQuad(a + 4 * dim + k));                                        \
      c40 = dpbusd(c40, x, b0);                                                                \
      c41 = dpbusd(c41, x, b1);                                                                \
      x = _mm256_set1_epi32(LoadQuad(a + 5 * dim + k));                                        \
      c50 = dpbusd(c50, x, b0);                                                                \
      c51 = dpbusd(c51, x, b1);                                                                \
    }                                                                                          \
    _mm256_storeu_ps(out, _mm256_cvtepi32_ps(c00));                                            \
    _mm256_storeu_ps(out + 8, _mm256_cvtepi32_ps(c01));                                        \
    _mm256_storeu_ps(out + ld, _mm256_cvtepi32_ps(c10));                                       \
    _mm256_storeu_ps(out + ld + 8, _mm256_cvtepi32_ps(c11));                                   \
    _mm256_storeu_ps(out + 2 * ld, _mm256_cvtepi32_ps(c20));                                   \
    _mm256_storeu_ps(out + 2 * ld + 8, _mm256_cvtepi32_ps(c21));                               \
    _mm256_storeu_ps(out + 3 * ld, _mm256_cvtepi32_ps(c30));                                   \
    _mm256_storeu_ps(out + 3 * ld + 8, _mm256_cvtepi32_ps(c31));                               \
    _mm256_storeu_ps(out + 4 * ld, _mm256_cvtepi32_ps(c40));                                   \
    _mm256_storeu_ps(out + 4 * ld + 8, _mm256_cvtepi32_ps(c41));                               \
    _mm256_storeu_ps(out + 5 * ld, _mm256_cvtepi32_ps(c50));                                   \
    _mm256_storeu_ps(out + 5 * ld + 8, _mm256_cvtepi32_ps(c51));                               \
  }

RAYTIME_DEFINE_VNNI_TILE(MicroKernel6x16AvxVnni, "avx2,avxvnni", _mm256_dpbusd_avx_epi32)
RAYTIME_DEFINE_VNNI_TILE(MicroKernel6x16Avx512Vnni, "avx2,avx512vnni,avx512vl", _mm256_dpbusd_epi32)
#undef RAYTIME_DEFINE_VNNI_TILE

// AVX-VNNI is CPUID leaf 7 sub-leaf 1, EAX bit 4: asked directly, as clang 14's
// __builtin_cpu_supports does not know it (its VEX encoding needs only the AVX state the AVX2
// check has confirmed).
bool CpuHasAvxVnni() {
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  return CpuHasAvx2Fma() && __get_cpuid_count(7, 1, &eax, &ebx, &ecx, &edx) && (eax & (1u << 4));
}
bool CpuHasAvx512Vnni() {
  return CpuHasAvx2Fma() && __builtin_cpu_supports("avx512vnni") &&
         __builtin_cpu_supports("avx512vl");
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
// the similarity of query row `row0` with reference column `col0`. Indices travel through the
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

// How each tile reads its operands: floats one dimension per step, or bytes four per step with
// A unsigned and B signed (b - 128, so the product needs 128·Σa added back); element (k, column)
// of a 16-column panel, and the dimension rounded up to the step (the pad is zero in A).
template <typename B>
size_t PanelOffset(int k, int column);
template <>
size_t PanelOffset<float>(int k, int column) {
  return size_t(k) * kPanelWidth + column;
}
template <>
size_t PanelOffset<int8_t>(int k, int column) {
  return size_t(k / 4) * 4 * kPanelWidth + 4 * column + k % 4;
}
template <typename B>
int KernelDim(int dim) {
  return std::is_same_v<B, int8_t> ? (dim + 3) / 4 * 4 : dim;
}
template <typename B>
B PanelValue(float value) {
  if constexpr (std::is_same_v<B, int8_t>) {
    return static_cast<int8_t>(static_cast<int>(value) - 128);
  } else {
    return value;
  }
}

// Not itself compiled for AVX2: only the micro-kernels and the scan are, so no Eigen code is
// generated with instructions the rest of the program does not assume.
template <typename A, typename B>
void FindNeighborsTiled(const Descriptors& a, const Descriptors& b,
                        void (*tile)(const A*, int, const B*, float*, int), std::vector<Top2>* rows,
                        std::vector<Top2>* cols) {
  const int n = a.rows, m = b.rows;
  const int dim = KernelDim<B>(a.dim);
  const int num_panels = (m + kPanelWidth - 1) / kPanelWidth;
  const int m_padded = num_panels * kPanelWidth;
  std::vector<B> packed(size_t(m_padded) * dim, B(0));
  for (int j = 0; j < m; ++j) {
    B* panel = packed.data() + size_t(j / kPanelWidth) * dim * kPanelWidth;
    for (int k = 0; k < b.dim; ++k) {
      panel[PanelOffset<B>(k, j % kPanelWidth)] = PanelValue<B>(b.values()[size_t(j) * b.dim + k]);
    }
  }
  const int n_padded = (n + kTileRows - 1) / kTileRows * kTileRows;
  std::vector<A> a_padded(size_t(n_padded) * dim, A(0));
  // What the tile's products miss of the exact dot product: 128·Σa for the signed bytes of B.
  std::vector<float> row_offset(n, 0.0f);
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < a.dim; ++k) {
      const float value = a.values()[size_t(i) * a.dim + k];
      a_padded[size_t(i) * dim + k] = static_cast<A>(value);
      if constexpr (std::is_same_v<B, int8_t>) row_offset[i] += 128.0f * value;
    }
  }

  std::vector<float> col_best(m_padded, kNoSimilarity), col_second(m_padded, kNoSimilarity);
  std::vector<int> col_index(m_padded, -1);
  std::vector<float> strip(size_t(kTileRows) * kBlockPanels * kPanelWidth);
  for (int p0 = 0; p0 < num_panels; p0 += kBlockPanels) {
    const int p1 = std::min(num_panels, p0 + kBlockPanels);
    const int width = (p1 - p0) * kPanelWidth;
    const int col0 = p0 * kPanelWidth;
    const int valid = std::min(width, m - col0);
    for (int r0 = 0; r0 < n_padded; r0 += kTileRows) {
      for (int p = p0; p < p1; ++p) {
        tile(a_padded.data() + size_t(r0) * dim, dim, packed.data() + size_t(p) * dim * kPanelWidth,
             strip.data() + (p - p0) * kPanelWidth, width);
      }
      const int rows_valid = std::min(kTileRows, n - r0);
      for (int r = 0; r < rows_valid; ++r) {
        float* values = strip.data() + size_t(r) * width;
        const float inverse_norm = a.inverse_norm[r0 + r];
        const float offset = row_offset[r0 + r];
        const float* column_norms = b.inverse_norm.data() + col0;
        for (int c = 0; c < valid; ++c) {
          values[c] = Similarity(values[c] + offset, inverse_norm, column_norms[c]);
        }
        // Padding columns must never win.
        for (int c = valid; c < width; ++c) values[c] = kNoSimilarity;
      }
      ScanStrip(strip.data(), rows_valid, width, r0, col0, rows->data(), col_best.data(),
                col_second.data(), col_index.data());
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
  const float* inverse_norm_a = nullptr;
  const float* inverse_norm_b = nullptr;
  int n = 0, m = 0, dim = 0;
  float max_error_sq = 0;
  std::vector<float> u2, v2, g2;  // padded to a multiple of 8 with NaN
  std::vector<float> lines;       // n x 3
  // Per line max_error^2 |l_i|_12^2, computed outside the AVX2 scan, where the compiler could fuse
  // it into a multiply-add the portable scan does not have.
  std::vector<float> bound;
};

void GuidedScanPortable(const GuidedInput& in, Top2* rows, Top2* cols) {
  for (int i = 0; i < in.n; ++i) {
    const float l0 = in.lines[3 * i], l1 = in.lines[3 * i + 1], l2 = in.lines[3 * i + 2];
    const float bound = in.bound[i];
    const float* ai = in.a + size_t(i) * in.dim;
    for (int j = 0; j < in.m; ++j) {
      // The AVX2 scan's expression, fused multiply-adds included, so both scans take the same
      // candidates (std::fma is exact everywhere, one instruction where the CPU has FMA).
      const float r = std::fma(l0, in.u2[j], std::fma(l1, in.v2[j], l2));
      if (!(r * r < std::fma(in.max_error_sq, in.g2[j], bound))) continue;
      const float* bj = in.b + size_t(j) * in.dim;
      float dot = 0.0f;
      for (int k = 0; k < in.dim; ++k) dot += ai[k] * bj[k];
      const float similarity = Similarity(dot, in.inverse_norm_a[i], in.inverse_norm_b[j]);
      rows[i].Add(similarity, j);
      cols[j].Add(similarity, i);
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
    const __m256 bound = _mm256_set1_ps(in.bound[i]);
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
        const float similarity = Similarity(DotAvx2(ai, in.b + size_t(j) * in.dim, in.dim),
                                            in.inverse_norm_a[i], in.inverse_norm_b[j]);
        rows[i].Add(similarity, j);
        cols[j].Add(similarity, i);
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
  MatchKernel kernel = MatchKernel::kAuto;
  if (EnumFromName(name, &kernel)) return kernel;
  throw InputError(UnknownKeyMessage(what, name, EnumValueNames<MatchKernel>(), "kernel"));
}

bool CpuHasAvx2Fma() { return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"); }

bool CpuHasVnni() { return CpuHasAvxVnni() || CpuHasAvx512Vnni(); }

MatchKernel ResolveMatchKernel(MatchKernel kernel) {
  if (kernel == MatchKernel::kAuto) {
    if (CpuHasVnni()) return MatchKernel::kVnni;
    return CpuHasAvx2Fma() ? MatchKernel::kAvx2 : MatchKernel::kGemm;
  }
  if (kernel == MatchKernel::kVnni && !CpuHasVnni()) {
    throw InputError(
        "matching kernel 'vnni' requested but this CPU lacks AVX-VNNI and AVX512-VNNI/VL (set "
        "matches.kernel to auto)");
  }
  if (kernel == MatchKernel::kAvx2 && !CpuHasAvx2Fma()) {
    throw InputError(
        "matching kernel 'avx2' requested but this CPU lacks AVX2/FMA (set matches.kernel to "
        "auto)");
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

void FindNeighbors(const ByteDescriptors& a_bytes, const ByteDescriptors& b_bytes,
                   MatchKernel kernel, NeighborList* a_to_b, NeighborList* b_to_a) {
  std::vector<Top2> rows(a_bytes.rows()), cols(b_bytes.rows());
  if (a_bytes.rows() > 0 && b_bytes.rows() > 0) {
    if (a_bytes.cols() != b_bytes.cols()) {
      throw std::invalid_argument("FindNeighbors: descriptor lengths differ (" +
                                  std::to_string(a_bytes.cols()) + " vs " +
                                  std::to_string(b_bytes.cols()) + ")");
    }
    const Descriptors a = Prepare(a_bytes), b = Prepare(b_bytes);
    switch (ResolveMatchKernel(kernel)) {
      case MatchKernel::kVnni:
        FindNeighborsTiled<uint8_t, int8_t>(
            a, b, CpuHasAvxVnni() ? MicroKernel6x16AvxVnni : MicroKernel6x16Avx512Vnni, &rows,
            &cols);
        break;
      case MatchKernel::kAvx2:
        FindNeighborsTiled<float, float>(a, b, MicroKernel6x16, &rows, &cols);
        break;
      default:
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

MatchList GuidedMatches(const ByteDescriptors& a_bytes, const ByteDescriptors& b_bytes,
                        const Eigen::Matrix<double, Eigen::Dynamic, 2>& x1,
                        const Eigen::Matrix<double, Eigen::Dynamic, 2>& x2,
                        const Eigen::Matrix3d& F, double max_error_px, double max_ratio,
                        double max_distance, bool mutual, MatchKernel kernel) {
  const int n = static_cast<int>(a_bytes.rows()), m = static_cast<int>(b_bytes.rows());
  const int dim = static_cast<int>(a_bytes.cols());
  if (x1.rows() != n || x2.rows() != m) {
    throw std::invalid_argument("GuidedMatches: keypoint and descriptor counts differ");
  }
  if (n == 0 || m == 0) return MatchList(0, 2);
  if (b_bytes.cols() != dim) {
    throw std::invalid_argument("GuidedMatches: descriptor lengths differ");
  }
  const Descriptors a = Prepare(a_bytes), b = Prepare(b_bytes);
  // The Sampson distance is invariant to the scale of F; unit norm keeps the float screening
  // well inside float range.
  const Eigen::Matrix3d Fn = F / F.norm();
  GuidedInput in;
  in.a = a.values();
  in.b = b.values();
  in.inverse_norm_a = a.inverse_norm.data();
  in.inverse_norm_b = b.inverse_norm.data();
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
  in.bound.resize(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d l = Fn * Eigen::Vector3d(x1(i, 0), x1(i, 1), 1.0);
    for (int c = 0; c < 3; ++c) in.lines[3 * i + c] = static_cast<float>(l(c));
    const float l0 = in.lines[3 * i], l1 = in.lines[3 * i + 1];
    in.bound[i] = in.max_error_sq * (l0 * l0 + l1 * l1);
  }
  std::vector<Top2> rows(n), cols(m);
  if (ResolveMatchKernel(kernel) != MatchKernel::kGemm) {
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

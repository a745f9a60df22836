// Nearest-neighbour descriptor matching kernels (SPEC §5, paper §4.1): ratio test and mutual
// check over one pair of images, and the guided second pass restricted to candidates near the
// epipolar lines of an estimated fundamental matrix.
//
// Descriptors are compared as unit vectors, so the squared L2 distance is 2 - 2 <a, b> and the
// nearest neighbours are the largest dot products: one dense product A B^T per pair gives both
// directions (rows: image 1 -> 2, columns: image 2 -> 1) for the mutual check. The products are
// taken on the quantized bytes, where they are integers computed exactly by every kernel, and
// scaled by the rows' inverse norms afterwards: the similarity (dot · 1/|a| · 1/|b| in float,
// a from the first image, for both directions) is the same to the bit whichever kernel ran, so
// every CPU finds the same matches.
//
// Which kernel: measured on the sample scene's real descriptors (bench/matcher_bench.cc, 1 thread,
// 8192 x 8192 RootSIFT descriptors; numbers in the header of that file): the AVX2/FMA register-
// blocked product with fused top-2 scans is several times faster than a blocked cv::gemm (ATLAS
// sgemm underneath) + scan, which is faster than cv::BFMatcher (float, k = 2, both directions);
// FLANN k-d trees are faster than BFMatcher but approximate (they miss true nearest neighbours,
// so the mutual check drops correct matches). On the bytes themselves, vpdpbusd (AVX-VNNI, or
// AVX512-VNNI on ymm registers) multiplies four times as many entries per instruction as a float
// FMA: 1.9x the AVX2 kernel's speed. kAuto picks VNNI, else AVX2, else the portable kernel.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "core/named_enum.h"

namespace raytime {

// Row-major, one descriptor per row.
using FloatDescriptors = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ByteDescriptors = Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
// Rows: index in image 1, index in image 2 (the layout of PairMatches::matches).
using MatchList = Eigen::Matrix<uint32_t, Eigen::Dynamic, 2, Eigen::RowMajor>;

enum class MatchKernel {
  kAuto,  // kVnni, else kAvx2, else kGemm: the fastest this CPU supports
  kVnni,  // AVX-VNNI / AVX512-VNNI byte products (vpdpbusd), 6 x 16 register tiles
  kAvx2,  // hand-blocked AVX2/FMA product, 6 x 16 register tiles, fused top-2 scan
  kGemm,  // cv::gemm on blocks of rows, then a scalar top-2 scan (portable)
};
constexpr std::array<EnumName<MatchKernel>, 4> EnumNames(MatchKernel) {
  return {{{MatchKernel::kAuto, "auto"},
           {MatchKernel::kVnni, "vnni"},
           {MatchKernel::kAvx2, "avx2"},
           {MatchKernel::kGemm, "gemm"}}};
}

// "auto", "vnni", "avx2", "gemm"; InputError naming `what` otherwise.
MatchKernel ParseMatchKernel(const std::string& name, const std::string& what);
inline const char* MatchKernelName(MatchKernel kernel) { return NameOf(kernel); }
bool CpuHasAvx2Fma();
bool CpuHasVnni();  // AVX2 and either AVX-VNNI or AVX512-VNNI with AVX512-VL
// kAuto resolved for this CPU; kVnni or kAvx2 on a CPU without it is a std::runtime_error.
MatchKernel ResolveMatchKernel(MatchKernel kernel);

// Unit-length float copies of quantized descriptors (all-zero rows stay zero), for matchers that
// work on floats (bench/matcher_bench.cc's OpenCV comparisons).
FloatDescriptors NormalizeDescriptors(const ByteDescriptors& descriptors);

// The two largest dot products of each query against all references, and the index of the
// largest. Ties go to the smallest index. With fewer than two references the missing
// similarities are -infinity.
struct NeighborList {
  std::vector<int> index;
  std::vector<float> best;
  std::vector<float> second;
};

// Top-2 neighbours of every row of `a` among the rows of `b` (a_to_b) and of every row of `b`
// among the rows of `a` (b_to_a), from one pass over the cosine similarities of the rows.
void FindNeighbors(const ByteDescriptors& a, const ByteDescriptors& b, MatchKernel kernel,
                   NeighborList* a_to_b, NeighborList* b_to_a);

// Lowe's ratio test on distances (best < max_ratio * second, distance = sqrt(2 - 2 dot)), an
// absolute bound (best < max_distance) and, when `mutual`, the same tests in the other direction
// plus agreement of both nearest neighbours (COLMAP's cross check). A missing second neighbour
// counts as orthogonal (distance sqrt(2)), as in COLMAP. Sorted by index in image 1.
MatchList RatioTestMatches(const NeighborList& a_to_b, const NeighborList& b_to_a, double max_ratio,
                           double max_distance, bool mutual);

// Guided matching (COLMAP's guided_matching): the same ratio test and mutual check, but each
// keypoint only competes with the keypoints of the other image whose Sampson distance under
// `F` (x2^T F x1 = 0, pixels) is below `max_error_px`. x1, x2: keypoint positions (rows x, y)
// in the pixel frame F refers to (undistorted when the camera has distortion). The kernel
// chooses the AVX2 (for kVnni and kAvx2) or portable screening of the n x m candidates; both
// evaluate the same float expressions (fused multiply-adds included), so they take the same
// candidates and find the same matches.
MatchList GuidedMatches(const ByteDescriptors& a, const ByteDescriptors& b,
                        const Eigen::Matrix<double, Eigen::Dynamic, 2>& x1,
                        const Eigen::Matrix<double, Eigen::Dynamic, 2>& x2,
                        const Eigen::Matrix3d& F, double max_error_px, double max_ratio,
                        double max_distance, bool mutual, MatchKernel kernel = MatchKernel::kAuto);

}  // namespace raytime

// Work split into a fixed number of chunks whatever the thread count, each chunk summing into its
// own copies and the copies added in chunk order afterwards: the sums, hence the solve and the
// uncertainty, are bit-identical on any number of threads (the ray-time LM's linearization, cost
// and back-substitution; the pose uncertainty's two passes).
#pragma once

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstddef>
#include <vector>

namespace raytime {

inline constexpr int kNumFixedChunks = 8;

// [0, n) split into kNumFixedChunks ranges of about equal weight, given the n + 1 prefix sums
// `weight_begin` of the items' weights: chunk k starts at the first item whose prefix reaches k/8
// of the total. Returns the kNumFixedChunks + 1 bounds.
inline std::vector<int> FixedChunkBounds(const std::vector<int>& weight_begin) {
  const int n = static_cast<int>(weight_begin.size()) - 1;
  const size_t total = static_cast<size_t>(weight_begin[n]);
  std::vector<int> bounds(kNumFixedChunks + 1, n);
  bounds[0] = 0;
  int i = 0;
  for (int k = 1; k < kNumFixedChunks; ++k) {
    const size_t target = total * k / kNumFixedChunks;
    while (i < n && static_cast<size_t>(weight_begin[i]) < target) ++i;
    bounds[k] = i;
  }
  return bounds;
}

// body(chunk) for every chunk, on at most num_threads threads.
template <typename Body>
void ForEachFixedChunk(int num_threads, const Body& body) {
  tbb::task_arena arena(std::max(1, num_threads));
  arena.execute([&] { tbb::parallel_for(0, kNumFixedChunks, [&](int chunk) { body(chunk); }); });
}

}  // namespace raytime

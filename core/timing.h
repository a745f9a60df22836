// Wall-clock durations for stage summaries and progress logs.
#pragma once

#include <chrono>

namespace raytime {

// Seconds from `start` (a steady_clock reading, immune to clock adjustments) to now.
inline double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace raytime

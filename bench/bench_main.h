// The one `main` of the benchmark programs: runs the program's own entry and reports a failure as
// the `raytime` command does, "NAME: message" on stderr and the exit status of its class
// (core/resource_failure.h: 2 bad input, 3 out of a resource, 1 otherwise).
//
//   int main(int argc, char** argv) { return raytime::BenchMain("matcher_bench", raytime::Main,
//   argc, argv); }
#pragma once

#include <cstdio>
#include <exception>

#include "core/resource_failure.h"

namespace raytime {

inline int BenchMain(const char* name, int (*entry)(int, char**), int argc, char** argv) {
  try {
    return entry(argc, argv);
  } catch (const std::exception& e) {
    const FailureDescription failure = DescribeFailure(e);
    std::fprintf(stderr, "%s: %s\n", name, failure.message.c_str());
    return failure.exit_code;
  }
}

}  // namespace raytime

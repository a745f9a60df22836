#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/, clang + ASan/UBSan) into build-fuzz/ and runs each
# for SECONDS (default 600), one after another as one process each at niceness FUZZ_NICE (default
# 19, the lowest CPU priority), printing seconds, executions, executions per second, corpus size,
# peak RSS and result per target. Exits non-zero when any target crashed.
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET ...]     (targets: tests/fuzz/corpus/*/)
#   FUZZ_NICE=10 scripts/fuzz.sh 600 tum
#   scripts/fuzz.sh 0                                      (only build)
#
# Each run starts from the committed seeds (tests/fuzz/corpus/TARGET) and keeps what it finds in
# build-fuzz/fuzz/corpus/TARGET, so a rerun continues where the last one stopped. A crashing input
# is saved as build-fuzz/fuzz/crashes/TARGET/crash-<sha1> (also leak-, timeout-, oom-), with the
# fuzzer's log beside it in build-fuzz/fuzz/logs/TARGET.log (the previous run's log is kept as
# TARGET.<date>.log). To reproduce one:
#   build-fuzz/tests/fuzz/TARGET_fuzzer build-fuzz/fuzz/crashes/TARGET/crash-...
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-600}"
shift || true
build=build-fuzz

export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$PWD/..}"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
# -O1 keeps the fuzzers fast; Debug keeps assertions (Eigen's bounds checks) on.
cmake -S . -B "$build" -G Ninja -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 \
  -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-g -O1" -DRAYTIME_FUZZ=ON "${launcher[@]}" \
  >/dev/null
nice ninja -C "$build" -j "${RAYTIME_JOBS:-2}" fuzzers
[ "$seconds" != 0 ] || exit 0  # libFuzzer reads -max_total_time=0 as no limit

if (($# > 0)); then
  targets=("$@")
else
  targets=()  # every target has its corpus folder (some share a source: capture_fuzzer.cc)
  for folder in tests/fuzz/corpus/*/; do
    targets+=("$(basename "$folder")")
  done
fi

# Parsers that take paths write their input below TMPDIR; a crashed process leaves its files
# there, so the whole folder goes at the end.
scratch=$(mktemp -d "$( [ -d /dev/shm ] && echo /dev/shm || echo /tmp)/raytime-fuzz.XXXXXX")
trap 'rm -rf "$scratch"' EXIT
export TMPDIR="$scratch"
# Crash on the first sanitizer report, with symbolized stacks.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"

printf '%-20s %8s %12s %8s %8s %8s  %s\n' target seconds executions exec/s corpus rss_mb result
failed=0
for name in "${targets[@]}"; do
  fuzzer="$build/tests/fuzz/${name}_fuzzer"
  [ -x "$fuzzer" ] || { echo "no fuzz target '$name' ($fuzzer)" >&2; exit 2; }
  corpus="$build/fuzz/corpus/$name"
  crashes="$build/fuzz/crashes/$name"
  log="$build/fuzz/logs/$name.log"
  mkdir -p "$corpus" "$crashes" "$(dirname "$log")"
  # A rerun keeps the previous run's log (a crash's, say) as TARGET.<its end time>.log.
  [ ! -f "$log" ] || mv "$log" "${log%.log}.$(date -r "$log" +%Y%m%d-%H%M%S).log"
  dict=()
  [ -f "tests/fuzz/dict/$name.dict" ] && dict=("-dict=tests/fuzz/dict/$name.dict")
  start=$(date +%s)
  status=0
  nice -n "${FUZZ_NICE:-19}" "$fuzzer" -max_total_time="$seconds" -timeout=30 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$crashes/" "${dict[@]}" \
    "$corpus" "tests/fuzz/corpus/$name" >"$log" 2>&1 || status=$?
  elapsed=$(($(date +%s) - start))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  if [ -z "$execs" ]; then  # a crash ends the run before the final stats
    execs=$(grep -oE '^#[0-9]+' "$log" | tail -1 | tr -d '#' || true)
  fi
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
  if [ -z "$rss" ]; then  # after a crash: the last status line's "rss: NMb"
    rss=$(grep -oE 'rss: [0-9]+Mb' "$log" | tail -1 | grep -oE '[0-9]+' || true)
  fi
  # libFuzzer's corpus (seeds and finds) on its last status line, else the files it kept.
  size=$(grep -oE 'corp: [0-9]+/' "$log" | tail -1 | grep -oE '[0-9]+' || true)
  [ -n "$size" ] || size=$(find "$corpus" -type f | wc -l)
  if ((status == 0)); then
    result=ok
  else
    result="CRASH (exit $status): $(grep -oE "$crashes/[^ ]+" "$log" | tail -1), log $log"
    failed=1
  fi
  printf '%-20s %8s %12s %8s %8s %8s  %s\n' "$name" "$elapsed" "${execs:-?}" "${rate:-?}" "$size" \
    "${rss:-?}" "$result"
done
exit "$failed"

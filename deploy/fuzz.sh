#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/) with clang, ASan and UBSan in ./build-fuzz and
# runs each for SECONDS (default 60) on a copy of its seed corpus, so the repository is never
# written. Prints the executions per target; exits non-zero if any target crashed, leaked or
# reported undefined behaviour (its log and the crashing input are kept and named).
#   deploy/fuzz.sh [SECONDS]
# Environment: FUZZ_JOBS (build parallelism, default 2), FUZZ_TARGETS (default: all six).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
targets="${FUZZ_TARGETS:-obj ply scene block wire store}"
clang="${CLANGXX:-$(command -v clang++-14 || command -v clang++)}"

cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER="$clang" -DRAYSTACK_FUZZ=ON -DRAYSTACK_BUILD_TESTS=OFF > /dev/null
cmake --build build-fuzz --target raystack_fuzzers -j "${FUZZ_JOBS:-2}"

work="$(mktemp -d /tmp/raystack-fuzz.XXXXXX)"
echo "fuzzing ${seconds}s per target; logs and findings in $work"
failed=0
printf '%-8s %12s %10s %8s  %s\n' target executions exec/s corpus result
for t in $targets; do
  corpus="$work/$t-corpus"
  mkdir -p "$corpus" "$work/$t-findings"
  cp tests/fuzz/corpus/"$t"/* "$corpus"/
  log="$work/$t.log"
  # -rss_limit_mb bounds what a hostile size field may make us allocate; a timeout of 10 s
  # on one input is a hang. The corpus copy grows as the fuzzer learns; the seeds do not.
  set +e
  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 \
    build-fuzz/tests/fuzz/"$t"_fuzz "$corpus" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 \
    -artifact_prefix="$work/$t-findings/" > "$log" 2>&1
  rc=$?
  set -e
  runs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)"
  speed="$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)"
  size="$(ls "$corpus" | wc -l)"
  if [ "$rc" -eq 0 ] && ! grep -q 'ERROR: \(AddressSanitizer\|LeakSanitizer\|libFuzzer\)\|runtime error:' "$log"; then
    result=ok
  else
    result="FAILED (exit $rc): $log, inputs in $work/$t-findings/"
    failed=1
  fi
  printf '%-8s %12s %10s %8s  %s\n' "$t" "$runs" "$speed" "$size" "$result"
done
if [ "$failed" -ne 0 ]; then
  echo "fuzz: at least one target failed" >&2
  exit 1
fi
rm -rf "$work"

#!/usr/bin/env bash
# Runs the libFuzzer targets of the parsers (fuzz/, issue 14), each for SECONDS, one after
# the other, and prints a table. Builds with Debian's clang (libFuzzer, ASan, UBSan) into
# ./build-fuzz, separate from ./build.
#   scripts/fuzz.sh                 # every target, 600 s each
#   scripts/fuzz.sh 60 csv camera   # two targets, 60 s each
# Seeds: fuzz/corpus/<target>/ (checked in, small) and fuzz/regressions/<target>/ (every
# input that ever failed); the corpus grows in build-fuzz/corpus/<target>/ (a working
# copy, kept between runs). A finding (crash, sanitizer report, escaping exception, an
# InputError that does not name the input, timeout > 10 s, more than 2 GB) stops that
# target's run: the input is in build-fuzz/artifacts/<target>/; minimize it
# (fuzz_<target> -minimize_crash=1 -runs=10000 FILE), fix the parser, and add the input to
# fuzz/regressions/<target>/ (tests/test_fuzz_regressions.cpp replays it in every build).
# Exit status: 0 when no target had a finding, 1 otherwise.
set -uo pipefail
cd "$(dirname "$0")/.."

seconds="${1:-600}"
shift || true
all_targets=(csv camera target robot logs setup png)
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then targets=("${all_targets[@]}"); fi
for t in "${targets[@]}"; do
  if [[ ! " ${all_targets[*]} " =~ " $t " ]]; then
    echo "fuzz: unknown target '$t'; expected one of: ${all_targets[*]}" >&2
    exit 2
  fi
done
if ! [[ "$seconds" =~ ^[0-9]+$ ]] || [ "$seconds" -lt 1 ]; then
  echo "fuzz: SECONDS must be a positive whole number, got '$seconds'" >&2
  exit 2
fi

# Longest input per target: text files far larger than any real one find nothing new and
# run slower; a PNG needs room for a few chunks.
max_len() {
  case "$1" in
    png) echo 65536 ;;
    camera | target) echo 8192 ;;
    *) echo 16384 ;;
  esac
}

CC="${CC:-clang-14}"
CXX="${CXX:-clang++-14}"
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache); fi
jobs="${MCMS_FUZZ_JOBS:-2}"

CC="$CC" CXX="$CXX" cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" \
  "${launcher[@]}" -DMCMS_BUILD_FUZZ=ON -DMCMS_BUILD_TESTS=OFF -DMCMS_BUILD_BENCH=OFF -DMCMS_BUILD_PYTHON=OFF >/dev/null ||
  { echo "fuzz: configuring build-fuzz failed" >&2; exit 2; }
cmake --build build-fuzz -j"$jobs" --target $(printf 'fuzz_%s ' "${targets[@]}") ||
  { echo "fuzz: building the targets failed" >&2; exit 2; }

# Leaks are findings too; UBSan stops at its first report (-fno-sanitize-recover=all).
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"

rows=()
status=0
for t in "${targets[@]}"; do
  corpus=build-fuzz/corpus/$t
  artifacts=build-fuzz/artifacts/$t
  mkdir -p "$corpus" "$artifacts"
  seeds=()
  for d in fuzz/corpus/$t fuzz/regressions/$t; do [ -d "$d" ] && seeds+=("$d"); done
  log=build-fuzz/fuzz_$t.log
  before=$(find "$artifacts" -type f | wc -l)
  echo "fuzz: $t for ${seconds} s (log: $log)"
  start=$(date +%s)
  # New inputs go to the first folder (the working copy); the seed folders are only read.
  dict=(); [ -f fuzz/dict/$t.dict ] && dict=(-dict=fuzz/dict/$t.dict)
  build-fuzz/fuzz/fuzz_$t "$corpus" "${seeds[@]}" "${dict[@]}" -max_len="$(max_len "$t")" -rss_limit_mb=2048 -timeout=10 \
    -max_total_time="$seconds" -print_final_stats=1 -artifact_prefix="$artifacts/" >"$log" 2>&1
  rc=$?
  elapsed=$(($(date +%s) - start))
  findings=$(($(find "$artifacts" -type f | wc -l) - before))
  if [ "$rc" -ne 0 ] && [ "$findings" -eq 0 ]; then findings=1; fi  # e.g. a failure before the first input
  if [ "$findings" -ne 0 ]; then status=1; fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  files=$(find "$corpus" -type f | wc -l)
  rows+=("$(printf '%-8s %8ss %12s %8s %6s %6s %7s %8s' "$t" "$elapsed" "${runs:-?}" "${speed:-?}" "${cov:-?}" "${ft:-?}" "$files" "$findings")")
  if [ "$findings" -ne 0 ]; then
    echo "fuzz: $t: finding (exit $rc); see $log and $artifacts/" >&2
    grep -m3 -E 'ERROR: |runtime error|uncaught exception|what\(\)' "$log" >&2 || true
  fi
done

printf '\n%-8s %9s %12s %8s %6s %6s %7s %8s\n' target time runs exec/s cov ft corpus findings
for r in "${rows[@]}"; do echo "$r"; done
exit $status

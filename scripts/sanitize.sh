#!/usr/bin/env bash
# AddressSanitizer + UndefinedBehaviorSanitizer build of the test suite, and a run of it.
# Builds into ./build-asan (separate from ./build).
#   scripts/sanitize.sh              # every module's unit tests + the app tests named below
#   MCMS_SANITIZE_MODULES="core vision" scripts/sanitize.sh   # a narrower subset
#   MCMS_SANITIZE_APP_TESTS="inputs cli fuse" (default)      # which tests/test_app_<what>.cpp
# The modules' tests are chosen by their ctest label (the <module> of test_<module>_*.cpp).
# Of the end-to-end app suites (the mcms binary, built instrumented too) only the bad-input,
# CLI and fusion ones run by default: the rendering-heavy ones take longer under the
# sanitizers than CI allows (all of them run uninstrumented in scripts/setup.sh test).
# Any sanitizer report fails the run: UBSan does not recover, ASan stops at the first error,
# LeakSanitizer runs at every test's exit.
set -euo pipefail
cd "$(dirname "$0")/.."

modules="${MCMS_SANITIZE_MODULES:-core vision model tracking fusion calib synthetic audit jobs app}"
app_tests="${MCMS_SANITIZE_APP_TESTS:-inputs cli fuse}"
jobs=$(nproc 2>/dev/null || echo 2)
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache); fi

san="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
# Under ASan, Eigen 3.4 stops trusting glibc's 16-byte malloc alignment and frees its heap
# matrices through its own aligned allocator, while Debian's prebuilt Ceres (built without
# ASan) allocates them with plain malloc: a Ceres-made matrix freed in our code (e.g.
# GradientChecker::ProbeResults) is then reported as a heap-buffer-overflow. Malloc is
# 16-byte aligned under ASan too, so tell Eigen, as the uninstrumented libraries assume.
san="$san -DEIGEN_MALLOC_ALREADY_ALIGNED=1"
# GCC 12 with -fsanitize reports -Wmaybe-uninitialized inside libstdc++'s own std::regex
# (std::function moved in regex_automaton.h; test_jobs_html_report uses std::regex): a known
# false positive of the instrumented build, not of our code, which the normal -Werror build
# still checks for this warning.
san="$san -Wno-maybe-uninitialized"
# -O1 -g keeps the tests fast enough and the reports readable; no NDEBUG, so the
# project's MCMS_DCHECK and Eigen's own assertions (index ranges, sizes) are on too.
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMCMS_WERROR=ON -DMCMS_BUILD_BENCH=OFF \
  "${launcher[@]}" \
  -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" \
  -DCMAKE_C_FLAGS="$san" -DCMAKE_CXX_FLAGS="$san" \
  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" -DMCMS_BUILD_PYTHON=OFF \
  -DMCMS_UNITY=OFF  # every source compiled from its own includes (a missing one hides in a unity batch)

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:check_initialization_order=1:strict_init_order=1:detect_stack_use_after_return=1}"

export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"

# Only the test executables of the chosen modules (their discovery runs them under the
# sanitizers already, at build time).
targets=()
labels=()
for m in $modules; do
  found=0
  for src in tests/test_"${m}"_*.cpp; do
    [ -e "$src" ] || continue
    name="$(basename "$src" .cpp)"
    if [ "$m" = app ]; then
      what="${name#test_app_}"
      case " $app_tests " in *" $what "*) ;; *) continue ;; esac
    fi
    targets+=("$name")
    found=1
  done
  if [ "$found" = 1 ]; then labels+=("$m"); fi
done
if [ ${#targets[@]} -eq 0 ]; then
  echo "sanitize: no tests/test_<module>_*.cpp for modules: $modules" >&2
  exit 2
fi
echo "sanitize: building ${targets[*]}"
case " $modules " in *" app "*) targets+=(mcms) ;; esac
cmake --build build-asan -j"$jobs" --target "${targets[@]}"

label_regex="^($(IFS='|'; echo "${labels[*]}"))\$"
echo "sanitize: running the tests labelled $label_regex"
# Test executables left unbuilt (the app suites not chosen) appear as <name>_NOT_BUILT.
ctest --test-dir build-asan --output-on-failure -j"$jobs" -L "$label_regex" -E '_NOT_BUILT$' 

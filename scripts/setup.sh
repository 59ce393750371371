#!/usr/bin/env bash
# One-step set-up on Debian bookworm: install the missing Debian packages, build,
# then either run the main job (demo) or the tests (test).
#   scripts/setup.sh demo   # install + build the mcms program only + `mcms demo` on the embedded
#                           # default scenario; prints where its HTML report is
#   scripts/setup.sh test   # install + build everything (tests, benchmarks) + the whole test suite
# Runs as root, or as a user with sudo. Builds into ./build.
set -euo pipefail
cd "$(dirname "$0")/.."

mode="${1:-}"
case "$mode" in
  demo|test) ;;
  *) echo "usage: scripts/setup.sh demo|test" >&2; exit 2 ;;
esac

# What building and running `mcms` needs (both modes).
packages=(
  build-essential cmake pkg-config
  ninja-build  # the generator: starts compiling sooner than make and keeps both cores busy
  ccache  # a rebuild after a small change recompiles only what changed (Ceres and OpenCV headers are slow)
  libeigen3-dev libopencv-dev libceres-dev libapriltag-dev libmrcal-dev
  libyaml-cpp-dev libcli11-dev nlohmann-json3-dev libboost-dev
  liburdfdom-dev  # robots as ROS describes them (model/urdf.h): urdfdom, with TinyXML and console_bridge
  zlib1g-dev
  libisal-dev  # the PNG frame reader (vision/image_file.h): ISA-L inflate and CRC-32
  libtiff-dev  # TIFF frames the mapped reader does not take (compressed), with libtiff's messages kept per file
)
# What only the tests, benchmarks and the Python module need (test mode): the demo does
# not wait for Chromium, Dask or the Python references to download.
test_packages=(
  libgtest-dev libgmock-dev libbenchmark-dev
  libspng-dev  # bench_throughput's comparison row of PNG readers (skipped without it)
  mrcal python3-mrcal python3-opencv python3-numpy pybind11-dev python3-dev
  python3-distributed  # `mcms batch`: Dask distributed (its test runs a local cluster)
  chromium  # the HTML report's test opens `mcms report` pages in headless Chromium (skipped without it)
)
if [ "$mode" = test ]; then packages+=("${test_packages[@]}"); fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing missing Debian packages: ${missing[*]}"
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
  "${sudo_cmd[@]}" apt-get update -q
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

jobs=$(nproc 2>/dev/null || echo 2)
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache); fi
generator=()
# Ninja for a new build tree; an existing one keeps the generator it was made with.
if [ ! -f build/CMakeCache.txt ] && command -v ninja >/dev/null 2>&1; then generator=(-G Ninja); fi
# The demo configures no tests or benchmarks (their packages may be missing); test mode
# turns them, and the Python module, on again in the same build tree (a demo configured
# before pybind11 was installed cached the module as off).
parts=(-DMCMS_BUILD_TESTS=ON -DMCMS_BUILD_BENCH=ON -DMCMS_BUILD_PYTHON=ON)
if [ "$mode" = demo ]; then parts=(-DMCMS_BUILD_TESTS=OFF -DMCMS_BUILD_BENCH=OFF); fi
cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DMCMS_WERROR=ON "${parts[@]}" "${launcher[@]}"
if [ "$mode" = demo ]; then
  cmake --build build -j"$jobs" --target mcms  # only the program: no tests, benchmarks or fuzz targets
  ./build/app/mcms demo -o mcms-demo
  echo "setup: the demo's results are in mcms-demo/; its report: $(pwd)/mcms-demo/report.html"
else
  cmake --build build -j"$jobs"
  ctest --test-dir build --output-on-failure -j"$jobs"
fi

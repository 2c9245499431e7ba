#!/usr/bin/env bash
# BIGUS-VTK setup: installs every dependency by Debian package name, configures and builds.
#
#   ./setup.sh main   set up, build, and run the main job on the bundled real liver sweep: train with
#                     frames i mod 4 == 2 held out, the trainer's defaults (the tracked poses refined: the
#                     sweep's neighbouring frames correlate) (BIGUS_TIME_BUDGET seconds, default 300), evaluate the held-out frames, write the report folder liver-report/
#   ./setup.sh test   set up, build, and run the whole test suite (what CI runs):
#                     ctest (GoogleTest + Python), the reader tests again under AddressSanitizer and
#                     UndefinedBehaviorSanitizer, and the libFuzzer target of the header parser
#   ./setup.sh build  set up and build only
#
# Environment: BIGUS_JOBS (parallel build jobs, default: number of cores),
#              BIGUS_FUZZ_SECONDS (fuzzing time in `test`, default 60),
#              BIGUS_TIME_BUDGET (training seconds in `main`, default 300).
set -euo pipefail
cd "$(dirname "$0")"
root=$(pwd)
jobs=${BIGUS_JOBS:-$(nproc)}

packages=(
  build-essential cmake ninja-build pkg-config
  libvtk9-dev python3-vtk9 vtk9 python3-dev python3-numpy
  libeigen3-dev libopencv-dev zlib1g-dev
  libopenmpi-dev openmpi-bin python3-mpi4py
  libgtest-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev
  clang libclang-rt-14-dev
  xvfb xauth
  paraview paraview-dev
)

install_dependencies() {
  local missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    return
  fi
  echo "setup: installing ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -q
  $sudo apt-get install -y -q --no-install-recommends "${packages[@]}"
}

# ParaView 5.11's Python side (pvpython, the `paraview` package and ParaView's own `vtkmodules`) is in
# python3-paraview, which conflicts with python3-vtk9 (a dependency of libvtk9-dev) because both put
# `vtkmodules` in /usr/lib/python3/dist-packages. So it is unpacked, not installed, into a side prefix
# that mirrors /usr: a real copy of ParaView's CMake package (its import files check that
# vtkmodules/*.so exist next to their own prefix) and links to everything else in /usr. Nothing in
# /usr changes; pvpython runs from there (build-paraview-prefix/usr/bin/pvpython).
paraview_prefix="$root/build-paraview-prefix"
prepare_paraview_prefix() {
  local usr="$paraview_prefix/usr" version
  dpkg-query -W -f='${Status}' paraview 2>/dev/null | grep -q "install ok installed" || return 0
  version=$(dpkg-query -W -f='${Version}' paraview)
  [ -e "$usr/lib/x86_64-linux-gnu/cmake/paraview-5.11/paraview-config.cmake" ] &&
    [ "$(cat "$paraview_prefix/version" 2>/dev/null)" = "$version" ] && return 0
  echo "setup: unpacking python3-paraview $version into $paraview_prefix"
  rm -rf "$paraview_prefix"
  mkdir -p "$paraview_prefix/deb"
  if ! (cd "$paraview_prefix/deb" && apt-get download -q "python3-paraview=$version" ||
    { apt-get update -q && apt-get download -q "python3-paraview=$version"; }); then
    echo "setup: could not download python3-paraview $version; the ParaView plugin is not built"
    rm -rf "$paraview_prefix"
    return 0
  fi
  dpkg-deb -x "$paraview_prefix"/deb/python3-paraview_*.deb "$paraview_prefix"
  rm -rf "$paraview_prefix/deb"
  link_missing() {
    mkdir -p "$2"
    local entry
    for entry in "$1"/*; do
      [ -e "$2/${entry##*/}" ] || [ -L "$2/${entry##*/}" ] || ln -s "$entry" "$2/${entry##*/}"
    done
  }
  mkdir -p "$usr/lib/x86_64-linux-gnu/cmake"
  cp -r /usr/lib/x86_64-linux-gnu/cmake/paraview-5.11 "$usr/lib/x86_64-linux-gnu/cmake/"
  for dir in bin include share lib lib/x86_64-linux-gnu lib/x86_64-linux-gnu/cmake \
    lib/x86_64-linux-gnu/vtk/hierarchy lib/x86_64-linux-gnu/vtk/hierarchy/ParaView; do
    link_missing "/usr/$dir" "$usr/$dir"
  done
  echo "$version" >"$paraview_prefix/version"
}

build() {
  prepare_paraview_prefix
  local paraview=()
  if [ -e "$paraview_prefix/version" ]; then
    paraview=(-DBIGUS_PARAVIEW_DIR="$paraview_prefix/usr/lib/x86_64-linux-gnu/cmake/paraview-5.11")
  fi
  cmake -S "$root" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE=Release "${paraview[@]}"
  cmake --build "$root/build" -j "$jobs"
}

run_tests() {
  local runner=()
  # Render tests need an X server; they skip (exit 125) where none is available.
  if [ -z "${DISPLAY:-}" ] && command -v xvfb-run >/dev/null; then
    runner=(xvfb-run -a)
  fi
  echo "== ctest (release build)"
  "${runner[@]}" ctest --test-dir "$root/build" --output-on-failure -j "$jobs"

  echo "== reader tests under AddressSanitizer + UndefinedBehaviorSanitizer"
  cmake -S "$root" -B "$root/build-asan" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DBIGUS_ENABLE_SANITIZERS=ON -DBIGUS_CUDA=OFF
  cmake --build "$root/build-asan" -j "$jobs"
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir "$root/build-asan" --output-on-failure -j "$jobs" -L "reader|filters|rendering|losses|reference|gapfilling"

  echo "== libFuzzer: sequence metafile header parser"
  cmake -S "$root/Testing/Fuzz" -B "$root/build-fuzz" -G Ninja -DCMAKE_CXX_COMPILER=clang++ \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo
  cmake --build "$root/build-fuzz" -j "$jobs"
  local seeds="$root/build-fuzz/seeds"
  mkdir -p "$seeds"
  # Seeds: the text headers of every metafile we ship (real sweeps and the malformed corpus).
  find "$root/Testing/Data" "$root/Examples/Data" \( -name '*.mha' -o -name '*.mhd' \) -print0 |
    while IFS= read -r -d '' f; do
      seed="$seeds/$(basename "$f").header"
      sed -n '1,/^ElementDataFile/p' "$f" >"$seed"
      truncate -s '<65536' "$seed"
    done
  local log="$root/build-fuzz/fuzz.log"
  if ! "$root/build-fuzz/FuzzMetaImageHeader" -max_total_time="${BIGUS_FUZZ_SECONDS:-60}" -max_len=65536 \
    -artifact_prefix="$root/build-fuzz/" -print_final_stats=1 "$seeds" >"$log" 2>&1; then
    tail -n 60 "$log"
    echo "fuzz: the header parser crashed (input saved by libFuzzer as crash-*)"
    return 1
  fi
  grep -E "^(Done|stat::number_of_executed_units)" "$log"
  echo "fuzz: no crash"
}

mode=${1:-}
case "$mode" in
  main)
    install_dependencies
    build
    sweep="$root/Examples/Data/liver/liver_sweep.igs.mha"
    report="$root/liver-report"
    mkdir -p "$report"
    "$root/build/bin/bigus" info "$sweep"
    "$root/build/bin/bigus" train "$sweep" -o "$report/liver_field.vtp" --holdout-every 4 --holdout-offset 2 \
      --time-budget "${BIGUS_TIME_BUDGET:-300}" --evaluate-every 30
    "$root/build/bin/bigus" evaluate "$report/liver_field.vtp" "$sweep" --holdout-every 4 --holdout-offset 2 \
      --refine-poses --report "$report"
    echo "report: $report (metrics.json, side-by-side PNGs, slice_orthogonal.png, slice_oblique.png," \
      "psnr_against_time.png, liver_field.vtp)"
    ;;
  test)
    install_dependencies
    build
    run_tests
    ;;
  build)
    install_dependencies
    build
    ;;
  *)
    sed -n '2,16p' "$0"
    exit 2
    ;;
esac

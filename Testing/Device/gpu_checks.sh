#!/bin/bash
# The GPU checks of a session lent a device (issue 58), in sections; no argument runs them all:
#   tests    the CUDA tests (machine.txt, tests.log)
#   ab       a fixed-step A/B of the CUDA training engine against an older build of its library (ab.log; only when
#            .bundle/old-libbigusCuda.so.0.1.0 is there, built against the same headers)
#   series   held-out PSNR against time on the GPU and on the CPU cores beside it (series-*.log, eval.log)
#   solve    the reflectivity solve on the device: the volume protocol's pixel-grid fit (80 slices) and a 2 M-unknown
#            one (the same volume at 0.18 mm pixels), --backend cuda against cpu on all cores (solve.log)
#   tracked  the main job at 60 s on the GPU scored at the held-out frames' tracked poses and fair (tracked.log)
#   routes   the same with variable projection and with the pixel-grid fit of every fan pixel (routes.log)
#   profile  the kernels' device time over 400 launches in a 800-step run (Nsight Compute's ncu; profile.log)
#   growth   the main job at 60 s as in tracked, with the growth stop relaxed and with a larger MaximumGaussians
#            (growth.log)
#   cutoff   the main job at 60 s as in tracked, trained at a footprint cut-off of 4 and of 3.5 standard deviations
#            from the first step (--training-cutoff; cutoff.log), against tracked's automatic one (4 in the pose
#            trial's branches, 3.5 before and, where it trusts the poses, after them)
#   dense    the main job at 60 s as in tracked, densifying the top 10 % to a maximum of 1 M Gaussians, with and
#            without the growth stop relaxed (dense.log; on 2 cores at the steps the device takes in 60 s, 10,000
#            steps so scored 40.11 dB, the defaults' 15,000 39.97: docs/FINDINGS.md, "The device's 60 s predicted")
#   bench    bigus benchmark --backend cuda: the gpu section (the main job at 10 to 100 s on the GPU and on the CPU
#            cores beside it), then the volume section (bench/BENCHMARKS_gpu.md, bench/BENCHMARKS_volume.md, bench.log)
# GPU_CHECKS_SECONDS (default 540): every command is stopped when the script has run that long, so that what ran
# comes back within the device call's limit.
#
# Here (a build with CUDA in build/):
#   ../shared/tools/device-bundle.sh build .bundle/bt bigus TestCudaRenderer TestCudaDevice TestGaussianMathCuda \
#     TestBackendCheck TestCudaBackendRegistry
#   (cd .bundle && tar cJf bt.tar.xz bt && rm -rf bt)
# On the device (the `device` tool's run, carry [".bundle"]): bash Testing/Device/gpu_checks.sh [SECTION...]
# Writes to $OUT (or ./gpu-checks). docs/FINDINGS.md has what each section printed on a device.
cd "$(dirname "$0")/../.." || exit 1
root=$PWD
out=${OUT:-$root/gpu-checks}
mkdir -p "$out" /tmp/w
# The test executables read their data from the build machine's source path.
[ -e /work/main ] || { mkdir -p /work && ln -s "$root" /work/main; }
tar xJf .bundle/bt.tar.xz -C /tmp && . /tmp/bt/env.sh || exit 1
mkdir -p /work/main/Testing/Output
L=$root/Examples/Data/liver/liver_sweep.igs.mha
H="--holdout-every 4 --holdout-offset 2"
sections=${*:-tests ab series solve tracked routes}
deadline=$((SECONDS + ${GPU_CHECKS_SECONDS:-540}))
left() { local t=$((deadline - SECONDS)); echo $((t > 1 ? t : 1)); } # seconds to the deadline
{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; lscpu | grep -E "Model name|^CPU\(s\)"; ls /usr/local/cuda*/bin | grep -E "^(nsys|ncu)$"; } \
  >"$out/machine.txt" 2>&1
TIMEFORMAT="wall %R s" # bash's time keyword: the wall time of a command (the device has no bc)

if [[ " $sections " == *" tests "* ]]; then
  {
    for t in TestCudaDevice TestGaussianMathCuda TestCudaBackendRegistry TestBackendCheck; do
      echo "== $t"; { time timeout $(left) $t; } 2>&1 | tail -5; echo "rc=${PIPESTATUS[0]}"
    done
    echo "== TestCudaRenderer"; { time timeout $(left) TestCudaRenderer; } 2>&1 | grep -vE "^\[ +(RUN|OK) "
    echo "rc=${PIPESTATUS[0]}"
  } >"$out/tests.log" 2>&1
fi

if [[ " $sections " == *" ab "* ]] && [ -f .bundle/old-libbigusCuda.so.0.1.0 ]; then
  cp -r /tmp/bt/lib /tmp/oldlib && cp .bundle/old-libbigusCuda.so.0.1.0 /tmp/oldlib/libbigusCuda.so.0.1.0
  for k in new old; do
    lib=/tmp/bt/lib; [ $k = old ] && lib=/tmp/oldlib
    echo "== $k"
    { time LD_LIBRARY_PATH=$lib timeout $(left) bigus train "$L" -o /tmp/w/ab-$k.vtp $H --iterations 2500 \
      --backend cuda; } 2>&1 | grep -v "^training "
  done >"$out/ab.log" 2>&1
fi

if [[ " $sections " == *" series "* ]]; then
  series() { # backend, cores, threads
    for B in 10 30 60 100; do
      echo "== $1 $B s"
      taskset -c "$2" bigus train "$L" -o /tmp/w/$1-$B.vtp $H --time-budget $B --backend $1 --threads $3 2>&1 |
        grep -v "^training "
    done
  }
  series cuda 0-3 4 >"$out/series-cuda.log" 2>&1 &
  series cpu 4-15 12 >"$out/series-cpu.log" 2>&1 &
  wait
  for f in /tmp/w/cuda-*.vtp /tmp/w/cpu-*.vtp; do
    echo "== $f"
    bigus evaluate "$f" "$L" $H --backend cuda --refine-poses --tracked-poses --report /tmp/w/r-$(basename "$f" .vtp) 2>&1
  done >"$out/eval.log" 2>&1
fi

if [[ " $sections " == *" solve "* ]]; then
  V=$root/Testing/Data/spine-phantom/SpinePhantomFreehandReconstructed.mha
  cd /tmp/w || exit 1
  {
    for case in "80 0" "80 0.18"; do
      set -- $case
      tag=s$2
      bigus sweep "$V" -o $tag.igs.mha --mask-output $tag-mask.mha --frames $1 --spacing $2 >/dev/null &&
        bigus sweep "$V" -o $tag-obl.igs.mha --mask-output $tag-obl-mask.mha --protocol oblique --frames 40 \
          --spacing $2 >/dev/null || echo "sweep failed"
      for backend in cuda cpu; do
        echo "== $tag $backend"
        { time bigus train $tag.igs.mha --mask $tag-mask.mha -o $tag-$backend.vtp --no-fill-gaps --backend $backend \
          --max-gaussians 2100000; } 2>&1 | grep -E "ElevationSigma|InitialGaussians|^field|^merge|^solves|^backend|wall|rror"
        bigus evaluate $tag-$backend.vtp $tag-obl.igs.mha --mask $tag-obl-mask.mha --backend cuda \
          --report r-$tag-$backend 2>&1 | grep -E "^  mean|rror"
      done
    done
  } >"$out/solve.log" 2>&1
  cd "$root" || exit 1
fi

# The main job at 60 s on the GPU scored at the held-out frames' tracked poses and fair: the defaults (tracked),
# variable projection (routes: --reflectivity-solve), the pixel-grid fit of every fan pixel (routes: a MaximumGaussians
# of half the liver's 29.4 M fan pixels, the assembled basis allowed 3/4 of the memory).
main60() { # name, options...
  local name=$1; shift
  echo "== $name: $*"
  { time timeout $(left) bigus train "$L" -o /tmp/w/$name.vtp $H --time-budget 60 --backend cuda "$@"; } 2>&1 |
    grep -E "^field|^early|RefinePoses|InitialGaussians|ElevationSigma|^merge|^solves|pose|wall|rror"
  timeout $(left) bigus evaluate /tmp/w/$name.vtp "$L" $H --backend cuda --refine-poses --tracked-poses --report /tmp/w/r-$name 2>&1 |
    grep -vE "^ +[0-9]+ "
}
[[ " $sections " == *" tracked "* ]] && main60 t60 >"$out/tracked.log" 2>&1
if [[ " $sections " == *" routes "* ]]; then
  {
    main60 vp60 --reflectivity-solve
    main60 grid --max-gaussians 15000000 --solve-memory 0.75
  } >"$out/routes.log" 2>&1
fi
if [[ " $sections " == *" profile "* ]]; then
  ncu=$(ls /usr/local/cuda*/bin/ncu 2>/dev/null | head -1)
  { time timeout $(left) "$ncu" --metrics gpu__time_duration.sum --launch-skip 4000 --launch-count 400 \
    --print-summary per-kernel bigus train "$L" -o /tmp/w/p.vtp $H --iterations 800 --backend cuda; } \
    >"$out/profile.log" 2>&1
fi
if [[ " $sections " == *" growth "* ]]; then
  {
    main60 patience --growth-patience 1000
    main60 max1m --growth-patience 1000 --max-gaussians 1000000
    main60 batch4 --frames-per-step 4
  } >"$out/growth.log" 2>&1
fi
if [[ " $sections " == *" cutoff "* ]]; then
  {
    main60 k4 --training-cutoff 4
    main60 k35 --training-cutoff 3.5
  } >"$out/cutoff.log" 2>&1
fi
if [[ " $sections " == *" dense "* ]]; then
  {
    main60 p10m1 --densify-percentile 10 --max-gaussians 1000000
    main60 p10m1patience --densify-percentile 10 --max-gaussians 1000000 --growth-patience 1000
  } >"$out/dense.log" 2>&1
fi
if [[ " $sections " == *" bench "* ]]; then
  for section in gpu volume; do
    echo "== bigus benchmark --section $section --backend cuda"
    { time timeout $(left) bigus benchmark --section $section --backend cuda --output "$out/bench" --data "$root"; } 2>&1 |
      grep -vE "^training "
  done >"$out/bench.log" 2>&1
fi
echo done

#!/bin/bash
# The GPU checks of a session lent a device (issue 58): the CUDA tests, a fixed-step A/B of the CUDA training engine
# against an older build of it, and held-out PSNR against time on the GPU and on the CPU cores beside it.
#
# Here (a build with CUDA in build/):
#   ../shared/tools/device-bundle.sh build .bundle/bt bigus TestCudaRenderer TestCudaDevice TestGaussianMathCuda \
#     TestBackendCheck TestCudaBackendRegistry
#   (cd .bundle && tar cJf bt.tar.xz bt && rm -rf bt)
#   optionally: cp OLD_BUILD/lib/libbigusCuda.so.0.1.0 .bundle/old-libbigusCuda.so.0.1.0   (the A/B's "old")
# On the device (the `device` tool's run, carry [".bundle"]): bash Testing/Device/gpu_checks.sh
# Writes machine.txt, tests.log, ab.log, series-cuda.log, series-cpu.log and eval.log to $OUT (or ./gpu-checks).
# About 7 minutes on an H200. docs/FINDINGS.md, "The image loss on the device", has what it printed there.
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
{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; lscpu | grep -E "Model name|^CPU\(s\)"; } \
  >"$out/machine.txt" 2>&1
{
  for t in TestCudaDevice TestGaussianMathCuda TestCudaBackendRegistry TestBackendCheck; do
    echo "== $t"; timeout 120 $t 2>&1 | tail -4; echo "rc=${PIPESTATUS[0]}"
  done
  echo "== TestCudaRenderer"; timeout 200 TestCudaRenderer 2>&1 | grep -vE "^\[ +(RUN|OK) "; echo "rc=${PIPESTATUS[0]}"
} >"$out/tests.log" 2>&1
if [ -f .bundle/old-libbigusCuda.so.0.1.0 ]; then
  cp -r /tmp/bt/lib /tmp/oldlib && cp .bundle/old-libbigusCuda.so.0.1.0 /tmp/oldlib/libbigusCuda.so.0.1.0
  for k in new old; do
    lib=/tmp/bt/lib; [ $k = old ] && lib=/tmp/oldlib
    echo "== $k"
    LD_LIBRARY_PATH=$lib bigus train "$L" -o /tmp/w/ab-$k.vtp $H --iterations 2500 --backend cuda 2>&1 | grep -v "^training "
  done >"$out/ab.log" 2>&1
fi
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
for f in /tmp/w/*.vtp; do
  echo "== $f"
  bigus evaluate "$f" "$L" $H --backend cuda --refine-poses --report /tmp/w/r-$(basename "$f" .vtp) 2>&1
done >"$out/eval.log" 2>&1
echo done

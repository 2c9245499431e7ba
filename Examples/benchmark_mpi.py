#!/usr/bin/env python3
"""MPI measurements of BIGUS-VTK: `bigus batch` throughput with 1 and 2 ranks over the bundled sweeps, and
data-parallel training (`bigus train --distributed`) at 2 ranks split into compute and sums across ranks, with
a model of the step time at more ranks. Writes docs/BENCHMARKS_mpi.md (and prints it).

Usage: benchmark_mpi.py [--bigus build/bin/bigus] [--mpiexec mpirun] [--iterations 200] [--output DIR]
Standard library only; every number in the report is measured by this run except the model's network
constants, which it names.
"""
import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIVER = os.path.join(ROOT, "Examples/Data/liver/liver_sweep.igs.mha")
SPINE = os.path.join(ROOT, "Testing/Data/spine-phantom/SpinePhantomFreehand.igs.mha")
SPINE_XML = os.path.join(ROOT, "Testing/Data/spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml")
NWIRE = os.path.join(ROOT, "Testing/Data/nwire-phantom/NwirePhantomFreehand.igs.mha")
NWIRE_XML = os.path.join(ROOT, "Testing/Data/nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml")

# The model's assumptions (not measured here): per-message latency of one ring step, link bandwidths.
LATENCY_S = 2e-6
LINKS_GBIT = (100, 400)
GPU_SPEEDUP = 100  # a step's compute on a GPU against one core of this machine, assumed (no GPU measured)


def mpi(mpiexec, ranks):
    return [mpiexec, "--oversubscribe", "-n", str(ranks)] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])


def peak_resident_mib(marker):
    """Each running `bigus` process (not mpirun) whose command line holds `marker` (bytes): pid -> its peak
    resident memory so far (VmHWM, MiB)."""
    peaks = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                command = f.read()
            if marker not in command or os.path.basename(command.split(b"\0")[0]) != b"bigus":
                continue
            with open(f"/proc/{pid}/status") as f:
                found = re.search(r"^VmHWM:\s+(\d+) kB", f.read(), re.M)
        except OSError:
            continue
        if found:
            peaks[int(pid)] = int(found.group(1)) / 1024
    return peaks


def run(command, marker=None):
    """Runs `command`; with `marker`, also samples (every 0.2 s) the peak resident memory of every bigus process
    whose command line holds it, and returns the largest value each reached (MiB, one per process)."""
    start = time.time()
    peaks = {}
    # Output to files, not pipes: nobody reads a pipe while the process is sampled.
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        process = subprocess.Popen(command, stdout=out, stderr=err, text=True)
        while process.poll() is None:
            for pid, mib in (peak_resident_mib(marker.encode()) if marker else {}).items():
                peaks[pid] = max(mib, peaks.get(pid, 0))
            time.sleep(0.2)
        out.seek(0)
        err.seek(0)
        result = subprocess.CompletedProcess(command, process.returncode, out.read(), err.read())
    if result.returncode not in (0, 1):
        sys.exit(f"{' '.join(command)} failed ({result.returncode}): {result.stderr[-2000:]}")
    return result, time.time() - start, sorted(peaks.values())


def batch_throughput(a, out):
    """The same manifest (the bundled sweeps, frames i mod 4 == 2 held out) in one process and on 2 ranks."""
    jobs = [
        {"name": "liver", "sweep": LIVER},
        {"name": "spine-phantom", "sweep": SPINE, "calibration": SPINE_XML},
        {"name": "nwire-phantom", "sweep": NWIRE, "calibration": NWIRE_XML},
        {"name": "liver-offset-0", "sweep": LIVER, "holdout-offset": 0},
    ]
    rows = []
    for ranks in (1, 2):
        folder = os.path.join(out, f"batch_{ranks}")
        os.makedirs(folder, exist_ok=True)
        manifest = os.path.join(folder, "manifest.json")
        with open(manifest, "w") as f:
            json.dump({"defaults": {"holdout-every": 4, "holdout-offset": 2, "iterations": a.iterations,
                                    "no-pixel-grid-fit": True, "seed": 1},
                       "jobs": [dict(j, output=j["name"]) for j in jobs]}, f, indent=2)
        for name in os.listdir(folder):
            if os.path.isdir(os.path.join(folder, name)):
                subprocess.run(["rm", "-rf", os.path.join(folder, name)])
        command = (mpi(a.mpiexec, ranks) if ranks > 1 else []) + [a.bigus, "batch", manifest]
        _, wall, _ = run(command)
        with open(os.path.join(folder, "summary.json")) as f:
            summary = json.load(f)
        rows.append((ranks, wall, summary))
    return rows


def distributed_training(a, out):
    """The liver, 2 frames per step: one process (2 threads) against 2 ranks of 1 frame and 1 thread each."""
    common = [LIVER, "--holdout-every", "4", "--holdout-offset", "2", "--no-pixel-grid-fit", "--iterations",
              str(a.iterations), "--seed", "1"]
    results = {}
    for ranks in (1, 2):
        field = os.path.join(out, f"liver_{ranks}.vtp")
        command = ([a.bigus, "train"] + common + ["--frames-per-step", "2", "-o", field] if ranks == 1 else
                   mpi(a.mpiexec, 2) + [a.bigus, "train"] + common + ["--distributed", "-o", field])
        result, _, peaks = run(command, marker=field)
        text = result.stdout
        found = re.search(r"field .*: (\d+) Gaussians \(from (\d+) seeds\) after (\d+) iterations in ([\d.]+) s", text)
        sums = re.search(r"distributed +\d+ ranks: ([\d.]+) s of ([\d.]+) s .*; ([\d.]+) MB summed per step", text)
        report = os.path.join(out, f"liver_{ranks}_report")
        run([a.bigus, "evaluate", field, LIVER, "--holdout-every", "4", "--holdout-offset", "2", "--report", report])
        with open(os.path.join(report, "metrics.json")) as f:
            psnr = json.load(f)["mean"]["psnr"]
        # The steps ran on the seeds (no densification within these steps); the field is pruned at the end.
        results[ranks] = {"gaussians": int(found.group(1)), "stepped": int(found.group(2)),
                          "iterations": int(found.group(3)), "seconds": float(found.group(4)),
                          "sums": float(sums.group(1)) if sums else 0.0,
                          "megabytes": float(sums.group(3)) if sums else 0.0, "psnr": psnr,
                          "peaks": peaks}
    return results


def mib(peaks):
    """Peak resident memory of each process of a run, as text."""
    return ", ".join(f"{p:.0f}" for p in peaks) if peaks else "not sampled"


def touched_per_frame(megabytes, gaussians):
    """The share of the field one frame touches, from the bytes a 2-rank step summed: one byte per Gaussian (which
    any rank touched), then 52 bytes (13 float32) per Gaussian either rank's frame touched, the union u2 of two
    frames; with frames touching independent shares f, u2 = 1 - (1 - f)^2."""
    union = min(1.0, max(0.0, (megabytes * 1e6 - gaussians) / (52 * gaussians)))
    return 1 - (1 - union) ** 0.5


def step_bytes(n, p, touched):
    """Bytes one step sums at P ranks: the touched flags (1 byte per Gaussian), then 52 bytes per Gaussian in the
    union of the P frames' shares."""
    return n, 52 * n * (1 - (1 - touched) ** p)


def allreduce_seconds(nbytes, p, bandwidth):
    """Ring allreduce of the step's two sums: 2 (P - 1) / P x bytes / bandwidth + 2 (P - 1) latencies each."""
    return sum(2 * (p - 1) / p * b / bandwidth + 2 * (p - 1) * LATENCY_S for b in nbytes)


def model_rows(step_compute_s, gaussians_measured, touched):
    """The step's sums against the compute of a step that renders 1 frame per rank, scaled linearly in the
    Gaussians from the measurement; each frame touching the share `touched` of the field."""
    rows = []
    for n in (200_000, 2_000_000):
        compute = step_compute_s * n / gaussians_measured
        for gbit in LINKS_GBIT:
            bandwidth = gbit * 1e9 / 8
            sizes = {p: sum(step_bytes(n, p, touched)) for p in (8, 64, 512)}
            times = {p: allreduce_seconds(step_bytes(n, p, touched), p, bandwidth) for p in (8, 64, 512)}
            # P at which the sums take as long as the compute (communication dominates beyond it), for this
            # machine's compute and for a compute GPU_SPEEDUP times faster.
            crossovers = [next((p for p in range(2, 1 << 20)
                                if allreduce_seconds(step_bytes(n, p, touched), p, bandwidth) >= c), None)
                          for c in (compute, compute / GPU_SPEEDUP)]
            rows.append((n, gbit, compute, sizes, times, crossovers))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bigus", default=os.path.join(ROOT, "build/bin/bigus"))
    parser.add_argument("--mpiexec", default="mpirun")
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--output", default=os.path.join(ROOT, "build/benchmark_mpi"))
    parser.add_argument("--report", default=os.path.join(ROOT, "docs/BENCHMARKS_mpi.md"))
    a = parser.parse_args()
    os.makedirs(a.output, exist_ok=True)
    batch = batch_throughput(a, a.output)
    training = distributed_training(a, a.output)
    one, two = training[1], training[2]
    step_one = one["seconds"] / one["iterations"]
    step_two = two["seconds"] / two["iterations"]
    compute_two = (two["seconds"] - two["sums"]) / two["iterations"]
    touched = touched_per_frame(two["megabytes"], two["stepped"])
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    lines = [
        "# MPI: batch throughput and data-parallel training",
        "",
        f"Written by `Examples/benchmark_mpi.py --iterations {a.iterations}` on {datetime.date.today()}, commit "
        f"{commit}, {platform.node()} ({os.cpu_count()} cores). Ranks on one machine share its cores "
        "(`mpirun --oversubscribe`); with 2 cores, 2 ranks run 1 thread each where one process runs 2.",
        "",
        "## `bigus batch` over the bundled sweeps",
        "",
        f"Four jobs (liver twice, spine phantom, N-wire; frames i mod 4 == 2 held out, {a.iterations} steps each "
        "from Harris seeds), trained and evaluated:",
        "",
        "| ranks | wall-clock (s) | jobs per hour | per job (s): mean +- sd | held-out PSNR (dB): mean +- sd |",
        "|---|---|---|---|---|",
    ]
    for ranks, wall, summary in batch:
        s = summary["statistics"]
        lines.append(f"| {ranks} | {wall:.1f} | {3600 * len(summary['jobs']) / wall:.0f} | "
                     f"{s['seconds']['mean']:.1f} +- {s['seconds']['sd']:.1f} | "
                     f"{s['psnr']['mean']:.2f} +- {s['psnr']['sd']:.2f} |")
    lines += [
        "",
        "## Data-parallel training: `bigus train --distributed` on the liver",
        "",
        f"{a.iterations} steps of 2 frames from the same seed: one process (2 threads, `--frames-per-step 2`) "
        "against 2 ranks (1 thread and 1 frame each). Sums: rank 0's seconds inside AllReduce, waiting for the "
        "other rank included (the two ranks' frames differ in cost).",
        "",
        "| run | Gaussians (in the steps / after the final prune) | s per step | of it in sums | MB summed per step | "
        "peak resident MiB per process | "
        "held-out PSNR (dB) |",
        "|---|---|---|---|---|---|---|",
        f"| 1 process | {one['stepped']} / {one['gaussians']} | {step_one:.4f} | - | - | {mib(one['peaks'])} | "
        f"{one['psnr']:.2f} |",
        f"| 2 ranks | {two['stepped']} / {two['gaussians']} | {step_two:.4f} | {two['sums'] / two['iterations']:.4f} | "
        f"{two['megabytes']:.3f} | {mib(two['peaks'])} | {two['psnr']:.2f} |",
        "",
        "What each rank holds: every training frame and mask (read by every rank), the whole field with its Adam "
        "moments and EA-D accumulators (identical on every rank), and one step's gradient buffer of 52 bytes per "
        "Gaussian with the packed copy of its touched entries for the sum. Memory per rank therefore does not fall "
        "with P (the peak resident memory above, sampled every 0.2 s from /proc, VmHWM); what P divides is the "
        "rendering of a step's frames "
        "(a step renders FramesPerStep x P frames, each rank its share) and the reflectivity solve's data-space "
        "vectors (each rank keeps the residual of its own frames).",
        "",
        "## Model of the step at more ranks",
        "",
        f"A step renders 1 frame per rank; its compute is this run's 2-rank compute per step "
        f"({compute_two * 1000:.1f} ms at the {two['stepped']} Gaussians the steps ran on, on one core), scaled "
        "linearly in the Gaussians. A step sums two things: one byte per Gaussian (which Gaussians any rank's frame "
        "touched, a maximum), then 13 float32 (52 bytes) per Gaussian in that union. From this run's bytes per "
        "step, one liver "
        f"frame touches {touched * 100:.1f} % of the field; the union of P frames is taken as 1 - (1 - "
        f"{touched:.3f})^P (frames touching independent shares: an assumption; along one long sweep, or several, "
        "a frame touches a smaller share and the union grows more slowly). Each sum is a ring allreduce: 2 (P - 1) "
        f"/ P x bytes / bandwidth + 2 (P - 1) x {LATENCY_S * 1e6:.0f} us latency (assumed, not measured). "
        "Communication dominates from the P in the last columns: with this machine's compute, and with a compute "
        f"{GPU_SPEEDUP} times faster (a GPU; assumed, not measured).",
        "",
        "| Gaussians | link | compute per step (ms) | MB per step P=8 / 64 / 512 | sums P=8 (ms) | P=64 | P=512 | "
        f"communication dominates from P = | the same, compute / {GPU_SPEEDUP} |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for n, gbit, compute, sizes, times, crossovers in model_rows(compute_two, two["stepped"], touched):
        cells = [f"{c:,}" if c else "beyond 10^6" for c in crossovers]
        lines.append(f"| {n:,} | {gbit} Gb/s | {compute * 1000:.1f} | "
                     f"{' / '.join(f'{sizes[p] / 1e6:.1f}' for p in (8, 64, 512))} | {times[8] * 1000:.2f} | "
                     f"{times[64] * 1000:.2f} | {times[512] * 1000:.2f} | {cells[0]} | {cells[1]} |")
    text = "\n".join(lines) + "\n"
    with open(a.report, "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()

"""`bigus train --distributed` under `mpirun -n 2 --oversubscribe` on the N-wire fixture against training in one
process with the same seed and the same frames per step (2 ranks x 1 frame = 1 process x 2 frames): the same
field after 50 steps (count, and parameters to float rounding) with only the touched Gaussians summed, the same
held-out PSNR (within 0.2 dB) after densification and reflectivity solves, the pixel-grid fit's distributed solve,
a checkpoint written by rank 0 resumed on 2 ranks, a rank that cannot read its checkpoint, a rank whose input
vtkGaussianFieldTrainer refuses (driven from Python with a vtkMPIController: distributed_trainer_rank.py) and a
killed rank, each of which ends the run instead of hanging it.

Usage: TestDistributedTraining.py TESTING_DATA_DIR BIGUS_EXECUTABLE MPIEXEC OUTPUT_DIR
"""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np

from mpi_testing import BIGUS, MPI, OUT, SWEEP, XML, check, field_arrays, find_rank, finish

COMMON = [SWEEP, "--calibration", XML, "--holdout-every", "4", "--holdout-offset", "2", "--threads", "1",
          "--seed", "7"]


def train(name, *options, ranks=0):
    """One process with 2 frames per step, or `ranks` ranks with 1 each; returns the field's path."""
    field = os.path.join(OUT, name + ".vtp")
    command = ([BIGUS, "train"] + COMMON + list(options) + ["--frames-per-step", "2", "-o", field] if not ranks
               else MPI + ["-n", str(ranks), BIGUS, "train"] + COMMON + list(options) + ["--distributed", "-o", field])
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    check(result.returncode == 0, f"{name}: exit {result.returncode}: {result.stderr[-800:]}")
    if ranks:
        check("Processes = 2" in result.stdout, f"{name}: no data-parallel setting line in {result.stdout[-800:]}")
    return field, result.stdout


def same_field(one, two, what, tolerance):
    a, b = field_arrays(one), field_arrays(two)
    check(len(a["Reflectivity"]) == len(b["Reflectivity"]),
          f"{what}: {len(a['Reflectivity'])} Gaussians in one process, {len(b['Reflectivity'])} on 2 ranks")
    if len(a["Reflectivity"]) != len(b["Reflectivity"]):
        return
    for key in a:
        scale = max(1e-6, float(np.abs(a[key]).max()))
        difference = float(np.abs(a[key] - b[key]).max()) / scale
        check(difference <= tolerance, f"{what}: {key} differs by {difference:.3g} of its largest value")


def held_out_psnr(field, name):
    report = os.path.join(OUT, name + "_report")
    result = subprocess.run([BIGUS, "evaluate", field, SWEEP, "--calibration", XML, "--holdout-every", "4",
                             "--holdout-offset", "2", "--report", report], capture_output=True, text=True)
    check(result.returncode == 0, f"evaluate {name}: {result.stderr}")
    with open(os.path.join(report, "metrics.json")) as f:
        return json.load(f)["mean"]["psnr"]


def without_hanging(command, what):
    """`command`'s result, or None (a failure recorded) when it had not ended after 120 s."""
    try:
        return subprocess.run(command, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        check(False, f"{what}: hung")
        return None


shutil.rmtree(OUT, ignore_errors=True)
os.makedirs(OUT)

# The first 50 steps: the same field (with 2 ranks the sum of two frames' gradients is the one process's).
adam = ["--no-pixel-grid-fit", "--iterations", "50"]
two, text = train("steps50_two", *adam, ranks=2)
same_field(train("steps50_one", *adam)[0], two, "50 steps", 1e-5)
# Only the Gaussians some rank's frame touched are summed (52 bytes each, after one byte per Gaussian saying which):
# fewer bytes than 52 per Gaussian of the field the steps ran on.
seeds = re.search(r"\(from (\d+) seeds\)", text)
summed = re.search(r"; ([\d.]+) MB summed per step", text)
check(seeds and summed and float(summed.group(1)) * 1e6 < 0.9 * 52 * int(seeds.group(1)),
      f"the sums of a step are not limited to the touched Gaussians: {text[-400:]}")

# Longer, with densification and reflectivity solves: the same count and held-out PSNR within 0.2 dB.
longer = ["--no-pixel-grid-fit", "--reflectivity-solve", "--iterations", "400"]
one, _ = train("steps400_one", *longer)
two, _ = train("steps400_two", *longer, ranks=2)
same_field(one, two, "400 steps with densification and solves", 1e-3)
p1, p2 = held_out_psnr(one, "steps400_one"), held_out_psnr(two, "steps400_two")
print(f"held-out PSNR after 400 steps: {p1:.3f} dB in one process, {p2:.3f} dB on 2 ranks")
check(abs(p1 - p2) <= 0.2, f"held-out PSNR {p1:.3f} (one process) and {p2:.3f} (2 ranks) differ by over 0.2 dB")

# The default for this little data, the pixel-grid fit, is a reflectivity solve alone: its A r and A^T y
# are split between the ranks.
same_field(train("grid_one")[0], train("grid_two", ranks=2)[0], "pixel-grid fit", 1e-4)

# Rank 0 writes the checkpoint; 2 ranks resume from it as one process does.
checkpoint = os.path.join(OUT, "distributed.ck")
train("checkpointed", "--no-pixel-grid-fit", "--iterations", "200", "--checkpoint", checkpoint, ranks=2)
check(os.path.exists(checkpoint), "rank 0 wrote no checkpoint")
resume = ["--no-pixel-grid-fit", "--iterations", "260", "--resume", checkpoint]
one, _ = train("resumed_one", *resume)
two, text = train("resumed_two", *resume, ranks=2)
check("after 260 iterations" in text, f"the resumed run did not reach 260 iterations: {text[-600:]}")
same_field(one, two, "resumed from rank 0's checkpoint", 1e-3)

# A rank that cannot read the checkpoint (rank 1 is given a file that is not one) fails every rank with a
# message, instead of leaving rank 0 waiting for it in the first sum.
broken = os.path.join(OUT, "broken.ck")
with open(broken, "wb") as f:
    f.write(b"not a checkpoint")
ranks = [COMMON + ["--no-pixel-grid-fit", "--iterations", "260", "--distributed", "-o",
                   os.path.join(OUT, "broken.vtp"), "--resume", ck] for ck in (checkpoint, broken)]
result = without_hanging(MPI + ["-n", "1", BIGUS, "train"] + ranks[0] + [":", "-n", "1", BIGUS, "train"] + ranks[1],
                         "training when rank 1 could not read its checkpoint")
if result:
    output = result.stdout + result.stderr
    check(result.returncode != 0, f"a rank without its checkpoint: exit {result.returncode}")
    check("broken.ck" in output and "another process failed (rank 1;" in output,
          f"a rank without its checkpoint: no word of the file and the rank in: {output[-800:]}")
check(not os.path.exists(os.path.join(OUT, "broken.vtp")), "a field was written by a run whose rank failed")

# The VTK filter with a vtkMPIController, as a Python program drives it: a rank whose input the filter refuses
# before training (a sweep that does not exist to hold out) fails every rank, each with a message, no hang.
script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "distributed_trainer_rank.py")
result = without_hanging(MPI + ["-n", "2", sys.executable, script, SWEEP, XML, "1"],
                         "the filter when rank 1's input was refused")
if result:
    check(result.returncode == 0 and "rank 1: 0 Gaussians; error: " in result.stdout and "HoldOutSweep 3" in
          result.stdout and "rank 0: 0 Gaussians; error: " in result.stdout and
          "another process failed (rank 1;" in result.stdout,
          f"the filter with a refused input on rank 1: exit {result.returncode}: {result.stdout[-800:]}")

# A rank that dies ends the run with an error on the others (Open MPI's runtime ends the job), not a hang.
process = subprocess.Popen(MPI + ["-n", "2", BIGUS, "train"] + COMMON +
                           ["--no-pixel-grid-fit", "--iterations", "100000", "--distributed", "-o",
                            os.path.join(OUT, "killed.vtp")], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True)
victim = find_rank(1, b"killed.vtp", process)
check(victim is not None, "could not find rank 1 to kill")
if victim is not None:
    time.sleep(2)  # into the training steps
    os.kill(victim, signal.SIGKILL)
try:
    output, _ = process.communicate(timeout=120)
    check(process.returncode != 0, f"the run with a killed rank exited {process.returncode}")
    check("signal 9" in output or "rank 1" in output, f"no word of the killed rank in: {output[-600:]}")
except subprocess.TimeoutExpired:
    process.kill()
    check(False, "training hung after rank 1 was killed")
check(not os.path.exists(os.path.join(OUT, "killed.vtp")), "a field was written by a run whose rank died")

finish()

"""`bigus batch` on the N-wire fixture, in one process and under `mpirun -n 2 --oversubscribe`: bad manifests
refused before any job starts with the line that is wrong; the same fields and metrics from 2 ranks as from one
process; a job with a malformed sweep reported while the others complete; a rank killed half-way ends the run
(no hang) and a rerun trains only the jobs without complete outputs (missing, or a field cut short); a job
whose arguments changed is trained again; an interrupted job with a checkpoint resumes from it; a job another
batch run holds is left to it.

Usage: TestBatch.py TESTING_DATA_DIR BIGUS_EXECUTABLE MPIEXEC OUTPUT_DIR
"""
import fcntl
import json
import os
import shutil
import signal
import subprocess
import time

from mpi_testing import BIGUS, DATA, MPI, OUT, SWEEP, XML, check, field_arrays, find_rank, finish

MALFORMED = os.path.join(DATA, "Malformed", "corrupt_body.igs.mha")


def write_manifest(folder, jobs, defaults=None, text=None):
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "manifest.json")
    with open(path, "w") as f:
        f.write(text if text is not None else json.dumps({"defaults": defaults or {}, "jobs": jobs}, indent=2))
    return path


def batch(manifest, ranks=0, timeout=600):
    command = (MPI + ["-n", str(ranks)] if ranks else []) + [BIGUS, "batch", manifest]
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout)


DEFAULTS = {"calibration": XML, "threads": 1, "seed": 7}
JOBS = [
    {"sweep": SWEEP, "output": "runs/grid", "holdout-every": 4, "holdout-offset": 1},
    {"sweep": SWEEP, "output": "runs/adam", "holdout-every": 4, "holdout-offset": 2, "no-pixel-grid-fit": True,
     "iterations": 60},
    {"sweep": MALFORMED, "output": "runs/malformed", "holdout-every": 4},
    {"sweep": SWEEP, "output": "runs/frames", "frames": [0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, 16, 17, 18],
     "no-pixel-grid-fit": True, "iterations": 40},
]


def bad_manifests():
    """Each bad manifest: exit 2, one message naming the line, and no job folder made."""
    folder = os.path.join(OUT, "bad")
    shutil.rmtree(folder, ignore_errors=True)
    good = {"sweep": SWEEP, "calibration": XML, "output": "a", "holdout-every": 4}
    cases = {
        # name: (manifest text, what the message must hold)
        "missing key": (json.dumps({"jobs": [good, {"sweep": SWEEP, "holdout-every": 4}]}, indent=2),
                        ["line 9", "job 1", "missing \"output\""]),
        "unknown option": (json.dumps({"jobs": [dict(good, **{"max-gausians": 100})]}, indent=2),
                           ["line 8", "\"max-gausians\"", "unknown option"]),
        "unknown option in defaults": (json.dumps({"defaults": {"iteration": 3}, "jobs": [good]}, indent=2),
                                       ["line 3", "\"defaults\" \"iteration\"", "unknown option"]),
        "path that does not exist": (json.dumps({"jobs": [good, dict(good, sweep="no_such.igs.mha", output="b")]},
                                                indent=2), ["line 9", "job 1", "no_such.igs.mha"]),
        "duplicate output": (json.dumps({"jobs": [good, dict(good, output="./a")]}, indent=2),
                             ["line 12", "job 1", "also job 0's (line 3)"]),
        "not JSON": ('{\n  "jobs": [\n    {"sweep": "x",\n     "output" "a"}\n  ]\n}\n', ["line 4", "not JSON"]),
        "no held-out frames": (json.dumps({"jobs": [{"sweep": SWEEP, "calibration": XML, "output": "a"}]}, indent=2),
                               ["line 3", "no held-out frames"]),
        "a job trained on every rank": (json.dumps({"jobs": [dict(good, distributed=True)]}, indent=2),
                                        ["line 8", "\"distributed\"", "not a batch option"]),
        "bad option value": (json.dumps({"jobs": [dict(good, iterations="many")]}, indent=2), ["line 3", "iterations"]),
        "negative iterations": (json.dumps({"jobs": [dict(good, iterations=-5)]}, indent=2),
                                ["line 3", "--iterations: '-5' is not at least 0"]),
        "duplicate name": (json.dumps({"jobs": [dict(good, name="x"), dict(good, name="x", output="b")]}, indent=2),
                           ["job 1", "\"name\"", "job name \"x\" is also job 0's (line 3)"]),
        "duplicate key": ('{\n  "jobs": [\n    {"sweep": "%s",\n     "output": "a",\n     "output": "b"}\n  ]\n}\n'
                          % SWEEP, ["\"output\" appears twice in one object (lines 4 and 5)"]),
    }
    for name, (text, expected) in cases.items():
        manifest = write_manifest(os.path.join(folder, name.replace(" ", "_")), None, text=text)
        result = batch(manifest)
        message = result.stderr.strip()
        check(result.returncode == 2, f"bad manifest ({name}): exit {result.returncode}, not 2 ({message})")
        check(len(message.splitlines()) == 1 and all(e in message for e in expected),
              f"bad manifest ({name}): message {message!r} lacks {expected}")
        made = [e for e in os.listdir(os.path.dirname(manifest)) if e != "manifest.json"]
        check(not made, f"bad manifest ({name}): {made} written though no job may start")


def same_jobs_on_one_process_and_two_ranks():
    """4 jobs, one with a malformed sweep: reported with its error, the others complete; on 2 ranks sharing the
    queue the fields and metrics are those of one process (same seed, one thread per job)."""
    results = {}
    for ranks in (0, 2):
        folder = os.path.join(OUT, f"ranks{ranks}")
        shutil.rmtree(folder, ignore_errors=True)
        manifest = write_manifest(folder, JOBS, DEFAULTS)
        result = batch(manifest, ranks)
        check(result.returncode == 1, f"{ranks} ranks: exit {result.returncode}, not 1 (a job failed): {result.stderr}")
        with open(os.path.join(folder, "summary.json")) as f:
            summary = json.load(f)
        check(summary["ranks"] == max(1, ranks), f"{ranks} ranks: summary says {summary['ranks']} ranks")
        statuses = [j["status"] for j in summary["jobs"]]
        check(statuses == ["done", "done", "failed", "done"], f"{ranks} ranks: statuses {statuses}")
        bad = summary["jobs"][2]
        check("corrupt_body.igs.mha" in bad.get("error", "") and "corrupt" in bad.get("error", ""),
              f"{ranks} ranks: the malformed job's error is {bad.get('error')!r}")
        check(summary["statistics"]["psnr"]["jobs"] == 3, f"{ranks} ranks: statistics over {summary['statistics']}")
        with open(os.path.join(folder, "summary.md")) as f:
            table = f.read()
        check("| malformed | failed |" in table and "mean +- sd (3 scored)" in table, f"{ranks} ranks: summary.md {table}")
        results[ranks] = (folder, summary)
    (one, s1), (two, s2) = results[0], results[2]
    for k, job in enumerate(JOBS):
        if s1["jobs"][k]["status"] != "done":
            continue
        name = os.path.basename(job["output"])
        a = field_arrays(os.path.join(one, "runs", name, "field.vtp"))
        b = field_arrays(os.path.join(two, "runs", name, "field.vtp"))
        for key in a:
            check(a[key].shape == b[key].shape and (a[key] == b[key]).all(),
                  f"job {name}: {key} differs between one process and 2 ranks")
        check(s1["jobs"][k]["metrics"] == s2["jobs"][k]["metrics"],
              f"job {name}: metrics {s1['jobs'][k]['metrics']} (one process) != {s2['jobs'][k]['metrics']} (2 ranks)")


def rank_killed_then_rerun():
    """Under mpirun -n 2, rank 1 killed once a job is complete: the run ends (non-zero, mpirun names the rank)
    instead of hanging; a rerun in one process trains only the jobs without complete outputs; after a change to
    one job's arguments, only that job."""
    folder = os.path.join(OUT, "killed")
    shutil.rmtree(folder, ignore_errors=True)
    slow = {"no-pixel-grid-fit": True, "iterations": 400, "holdout-every": 4}
    jobs = [dict(slow, sweep=SWEEP, output=f"runs/job{k}", **{"holdout-offset": k % 4}) for k in range(6)]
    manifest = write_manifest(folder, jobs, DEFAULTS)
    process = subprocess.Popen(MPI + ["-n", "2", BIGUS, "batch", manifest], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    records = lambda: [k for k in range(6) if os.path.exists(os.path.join(folder, "runs", f"job{k}", "job.json"))]
    deadline = time.time() + 300
    while not records() and time.time() < deadline and process.poll() is None:
        time.sleep(0.2)
    victim = find_rank(1, manifest.encode(), process)
    check(victim is not None, "could not find rank 1 to kill")
    if victim is None:
        process.kill()
        return
    os.kill(victim, signal.SIGKILL)
    try:
        output, _ = process.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        process.kill()
        check(False, "the batch hung after rank 1 was killed")
        return
    check(process.returncode != 0, f"the batch with a killed rank exited {process.returncode}")
    check("rank 1" in output or "signal 9" in output, f"no word of the killed rank in: {output[-600:]}")
    complete = records()
    check(0 < len(complete) < 6, f"{len(complete)} jobs complete before the kill (expected some, not all)")
    # Half-written outputs must not count: a field without its job.json (a job the kill interrupted), and a
    # complete job's field cut short after its job.json was written (a disk that filled, a copy interrupted).
    missing = [k for k in range(6) if k not in complete]
    os.makedirs(os.path.join(folder, "runs", f"job{missing[0]}"), exist_ok=True)
    with open(os.path.join(folder, "runs", f"job{missing[0]}", "field.vtp"), "w") as f:
        f.write("<VTKFile half written")
    cut = complete[0]
    path = os.path.join(folder, "runs", f"job{cut}", "field.vtp")
    os.truncate(path, os.path.getsize(path) // 2)
    kept = [k for k in complete if k != cut]
    times = {k: os.path.getmtime(os.path.join(folder, "runs", f"job{k}", "field.vtp")) for k in kept}
    result = batch(manifest)
    check(result.returncode == 0, f"rerun exit {result.returncode}: {result.stderr}")
    summary = read_summary(folder)
    check(summary["kept"] == len(kept) and summary["done"] == 6 - len(kept),
          f"rerun: kept {summary['kept']} done {summary['done']}, expected {len(kept)} / {6 - len(kept)}")
    for k, t in times.items():
        check(os.path.getmtime(os.path.join(folder, "runs", f"job{k}", "field.vtp")) == t,
              f"job{k} was complete and was trained again")
    check(all(summary["jobs"][k]["status"] == "done" for k in missing + [cut]), f"rerun statuses {summary['jobs']}")
    # A job whose arguments changed since its outputs were written is trained again, and only that one.
    jobs[missing[-1]]["iterations"] = 100
    write_manifest(folder, jobs, DEFAULTS)
    result = batch(manifest)
    summary = read_summary(folder)
    check(result.returncode == 0 and summary["kept"] == 5 and summary["done"] == 1 and
          summary["jobs"][missing[-1]]["status"] == "done",
          f"changed arguments: exit {result.returncode}, kept {summary['kept']} done {summary['done']}")


def interrupted_job_resumes_from_its_checkpoint():
    """A job whose outputs are not complete but whose checkpoint is there goes on from it: the first run's checkpoint
    (written every 20 steps) is kept, its job.json removed as a kill would leave it, and the rerun resumes at the
    checkpoint's step; a checkpoint written with other options is refused, naming them, and the job trained afresh."""
    folder = os.path.join(OUT, "resume")
    shutil.rmtree(folder, ignore_errors=True)
    job = {"sweep": SWEEP, "output": "runs/job", "holdout-every": 4, "holdout-offset": 2, "no-pixel-grid-fit": True,
           "iterations": 60, "checkpoint": "state.ckpt", "checkpoint-interval": 20}
    manifest = write_manifest(folder, [job], DEFAULTS)
    result = batch(manifest)
    check(result.returncode == 0, f"first run: exit {result.returncode}: {result.stderr}")
    run = os.path.join(folder, "runs", "job")
    check(os.path.exists(os.path.join(run, "state.ckpt")), "no checkpoint written")
    os.remove(os.path.join(run, "job.json"))
    result = batch(manifest)
    with open(os.path.join(run, "log.txt")) as f:
        log = f.read()
    check(result.returncode == 0 and read_summary(folder)["done"] == 1, f"rerun: exit {result.returncode}")
    check("resuming from the checkpoint" in log and "after 60 iterations" in log,
          f"the rerun did not resume: {log[-800:]}")
    os.remove(os.path.join(run, "job.json"))
    job["elevation-sigma"] = 0.9
    write_manifest(folder, [job], DEFAULTS)
    result = batch(manifest)
    with open(os.path.join(run, "log.txt")) as f:
        log = f.read()
    check(result.returncode == 0 and read_summary(folder)["done"] == 1 and "ElevationSigma" in log and
          "could not be resumed" in log, f"a checkpoint of other options: exit {result.returncode}, log {log[-600:]}")


def a_job_another_run_holds_is_left_to_it():
    """Two batch runs of one manifest never train one job at once: a job whose folder lock another process holds
    (flock on OUTPUT/.bigus-batch.lock, as a second `bigus batch` takes it) is reported busy, its folder untouched,
    the run's exit 0; once the lock is released, a rerun trains it."""
    folder = os.path.join(OUT, "lock")
    shutil.rmtree(folder, ignore_errors=True)
    job = {"sweep": SWEEP, "output": "runs/job", "holdout-every": 4, "holdout-offset": 2}
    manifest = write_manifest(folder, [job], DEFAULTS)
    run = os.path.join(folder, "runs", "job")
    os.makedirs(run)
    with open(os.path.join(run, ".bigus-batch.lock"), "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        result = batch(manifest)
        summary = read_summary(folder)
        check(result.returncode == 0 and summary["busy"] == 1 and summary["done"] == 0 and
              "left to the run that holds it" in result.stdout, f"held: exit {result.returncode}, {result.stdout}")
        check(os.listdir(run) == [".bigus-batch.lock"], f"the held job's folder was touched: {os.listdir(run)}")
    result = batch(manifest)
    check(result.returncode == 0 and read_summary(folder)["done"] == 1, f"released: exit {result.returncode}")


def read_summary(folder):
    with open(os.path.join(folder, "summary.json")) as f:
        return json.load(f)


bad_manifests()
same_jobs_on_one_process_and_two_ranks()
rank_killed_then_rerun()
interrupted_job_resumes_from_its_checkpoint()
a_job_another_run_holds_is_left_to_it()
finish()

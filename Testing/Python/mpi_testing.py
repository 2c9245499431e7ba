"""What the MPI tests (TestBatch.py, TestDistributedTraining.py) share: their arguments, the N-wire fixture,
the mpirun command, failure bookkeeping, reading a field, and finding a rank's process to kill.

Both scripts take: TESTING_DATA_DIR BIGUS_EXECUTABLE MPIEXEC OUTPUT_DIR
"""
import os
import sys
import time

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

DATA, BIGUS, OUT = (os.path.abspath(a) for a in (sys.argv[1], sys.argv[2], sys.argv[4]))
NWIRE = os.path.join(DATA, "nwire-phantom")
SWEEP = os.path.join(NWIRE, "NwirePhantomFreehandCropped.igs.mha")
XML = os.path.join(NWIRE, "PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml")
# As root (containers, CI) Open MPI wants to be told; --oversubscribe: more ranks than cores.
MPI = [sys.argv[3], "--oversubscribe"] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])
failures = []


def check(condition, what):
    if not condition:
        failures.append(what)
        print("FAIL:", what)


def finish():
    if failures:
        print(f"{len(failures)} failures")
        sys.exit(1)
    print("ok")


def field_arrays(path):
    """A field's means, Scale, Rotation and Reflectivity as float64 arrays."""
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(path)
    reader.Update()
    field = reader.GetOutput()
    arrays = {"Means": vtk_to_numpy(field.GetPoints().GetData()).astype(np.float64)}
    for name in ("Scale", "Rotation", "Reflectivity"):
        arrays[name] = vtk_to_numpy(field.GetPointData().GetArray(name)).astype(np.float64)
    return arrays


def find_rank(rank, marker, process, timeout=120):
    """The pid of MPI rank `rank` whose command line holds `marker` (bytes), started by `process` (mpirun);
    None when it does not appear within `timeout` seconds or mpirun ended."""
    deadline = time.time() + timeout
    while time.time() < deadline and process.poll() is None:
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{pid}/environ", "rb") as f:
                    environment = f.read().split(b"\0")
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    command = f.read()
            except OSError:
                continue
            if f"OMPI_COMM_WORLD_RANK={rank}".encode() in environment and marker in command:
                return int(pid)
        time.sleep(0.5)
    return None

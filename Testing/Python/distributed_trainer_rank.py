"""One rank of TestDistributedTraining's filter case, run under mpirun: vtkGaussianFieldTrainer given a
vtkMPIController, every rank reading the same sweep, and the rank named on the command line asking for a sweep
that does not exist (HoldOutSweep 3), so that the filter refuses its input before training. Prints the filter's
error message; exits 0 when this rank reports an error and no field (a hang is what the caller watches for).

Usage: mpirun -n 2 python3 distributed_trainer_rank.py SWEEP CALIBRATION REFUSING_RANK
"""
import sys

from mpi4py import MPI  # noqa: F401  (initialises MPI, which vtkMPIController.Initialize() from Python expects)
import vtk
from vtkmodules.vtkParallelMPI import vtkMPIController

import bigus

controller = vtkMPIController()
controller.Initialize()
rank = controller.GetLocalProcessId()
reader = bigus.vtkUltrasoundSequenceReader()
reader.SetFileName(sys.argv[1])
reader.SetCalibrationFileName(sys.argv[2])
trainer = bigus.vtkGaussianFieldTrainer()
trainer.SetInputConnection(reader.GetOutputPort())
trainer.SetController(controller)
trainer.SetIterations(20)
if rank == int(sys.argv[3]):
    trainer.SetHoldOutSweep(3)
messages = []


@vtk.calldata_type(vtk.VTK_STRING)
def on_error(caller, event, text):
    messages.append(text.strip().splitlines()[-1])


trainer.AddObserver(vtk.vtkCommand.ErrorEvent, on_error)
trainer.Update()
print(f"rank {rank}: {trainer.GetNumberOfGaussians()} Gaussians; error: {' | '.join(messages)}", flush=True)
controller.Finalize()
sys.exit(0 if messages and trainer.GetNumberOfGaussians() == 0 else 1)

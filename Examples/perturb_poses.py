"""Write a copy of a tracked sweep whose poses carry simulated tracker errors, to test pose refinement on real images.

Each frame's ImageToReference is moved by its own rigid motion: a rotation of DEGREES about a random axis
(uniform on the sphere) through the frame's centre pixel, then a translation of MM in a random direction
(numpy's default_rng(SEED), frames in order). The images, timestamps and every other field are copied
unchanged; the output is written by vtkUltrasoundSequenceWriter (ImageToReference per frame, as PLUS writes it).
The errors are independent from frame to frame, as a tracker's jitter is, so `bigus train` starts the pose
corrections from the first step on such a sweep (the tracked path jitters by more than 0.35 mm from frame to
frame; docs/FINDINGS.md, "The pose refinement's start chosen from the tracked path").
Only numpy and the project's Python module. Usage (after ./setup.sh build):
  PYTHONPATH=build/lib/python3/dist-packages python3 Examples/perturb_poses.py \\
      Examples/Data/liver/liver_sweep.igs.mha liver_jittered.igs.mha --degrees 0.5 --mm 0.5 --seed 5
"""
import argparse

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

import bigus


def rotation(axis_angle):
    """The rotation matrix of a rotation vector (rad), by Rodrigues' formula."""
    angle = np.linalg.norm(axis_angle)
    if angle == 0:
        return np.eye(3)
    k = axis_angle / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("sweep", help="tracked sweep to read (.igs.mha)")
    parser.add_argument("output", help="sweep to write (.igs.mha); must differ from the input")
    parser.add_argument("--calibration", help="PLUS device-set configuration XML (ImageToProbe) of the sweep")
    parser.add_argument("--degrees", type=float, default=0.5, help="rotation of each frame, degrees")
    parser.add_argument("--mm", type=float, default=0.5, help="translation of each frame, mm")
    parser.add_argument("--seed", type=int, default=5)
    args = parser.parse_args()
    reader = bigus.vtkUltrasoundSequenceReader()
    reader.SetFileName(args.sweep)
    if args.calibration:
        reader.SetCalibrationFileName(args.calibration)
    reader.Update()
    image = reader.GetOutput()
    w, h, n = image.GetDimensions()
    if n == 0:
        raise SystemExit("%s: no frames read" % args.sweep)
    poses = vtk_to_numpy(image.GetFieldData().GetArray("ImageToReference")).reshape(n, 4, 4).copy()
    rng = np.random.default_rng(args.seed)
    for k in range(n):
        axis = rng.normal(size=3)
        shift = rng.normal(size=3)
        r = rotation(axis / np.linalg.norm(axis) * np.deg2rad(args.degrees))
        centre = poses[k, :3, :3] @ np.array([(w - 1) / 2, (h - 1) / 2, 0]) + poses[k, :3, 3]
        motion = np.eye(4)
        motion[:3, :3] = r
        motion[:3, 3] = centre - r @ centre + shift / np.linalg.norm(shift) * args.mm
        poses[k] = motion @ poses[k]
    moved = numpy_to_vtk(poses.reshape(n, 16), deep=1)
    moved.SetName("ImageToReference")
    image.GetFieldData().RemoveArray("ImageToReference")
    image.GetFieldData().AddArray(moved)
    writer = bigus.vtkUltrasoundSequenceWriter()
    writer.SetInputData(image)
    writer.SetFileName(args.output)
    if not writer.Write():
        raise SystemExit("%s: not written" % args.output)
    print("wrote %s: %d frames, each moved by %.3g degrees and %.3g mm at random (seed %d)" % (
        args.output, n, args.degrees, args.mm, args.seed))


if __name__ == "__main__":
    main()

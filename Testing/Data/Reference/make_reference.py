"""Regenerates the committed reference results of TestReferenceResults (see README.md in this folder).

Trains the reference field on the N-wire fixture with `bigus train`, records its held-out and training
PSNR with `bigus evaluate`, renders four reference slices and stacks with vtkGaussianFieldReslice and writes them
as float MetaImages, and writes reference.json: the training settings, the recorded PSNR values and the
geometry of every plane (the test replays exactly that geometry).

Usage, from the repository root after a build:
  PYTHONPATH=build/lib/python3/dist-packages /usr/bin/python3 Testing/Data/Reference/make_reference.py build/bin/bigus
With `--spread N` it writes nothing and instead trains with seeds 1 to N (the same settings otherwise)
and prints their PSNR values: the run-to-run spread that a change of training has to be judged against.
"""
import json
import math
import os
import subprocess
import sys
import tempfile

import vtk
from vtk.util.numpy_support import vtk_to_numpy
import bigus

HERE = os.path.dirname(os.path.abspath(__file__))
FIXTURE = os.path.join(HERE, "..", "nwire-phantom")
SWEEP = "NwirePhantomFreehandCropped.igs.mha"
CALIBRATION = "PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml"
FIELD = "nwire_reference.vtp"
SWEEP_ARGS = [os.path.join(FIXTURE, SWEEP), "--calibration", os.path.join(FIXTURE, CALIBRATION)]

# A short deterministic run: a few thousand Gaussians, about 3 s on one thread. The test trains with
# these settings (read back from reference.json) on the same thread count.
TRAINING = {
    "holdout_every": 4,
    "holdout_offset": 2,
    "iterations": 600,
    "initial_gaussians": 2000,
    "max_gaussians": 4000,
    "elevation_sigma": 0.5,
    "coarse_fraction": 0,
    "refine_poses": 0,
    "training_cutoff": 4,
    "seed": 1,
    "threads": 1,
}


def run(*args):
    result = subprocess.run(list(args), capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit("%s failed:\n%s%s" % (" ".join(args), result.stdout, result.stderr))
    return result.stdout


def mean_psnr(bigus_exe, field, frame_args):
    with tempfile.TemporaryDirectory() as report:
        run(bigus_exe, "evaluate", field, *SWEEP_ARGS, *frame_args, "--report", report)
        with open(os.path.join(report, "metrics.json")) as f:
            return json.load(f)["mean"]["psnr"]


def train(bigus_exe, field, seed):
    """Trains with TRAINING's settings and @p seed; returns the field and its training frames, held-out
    PSNR and training PSNR (dB, as `bigus evaluate` reports them)."""
    t = TRAINING
    run(bigus_exe, "train", *SWEEP_ARGS, "-o", field, "--holdout-every", str(t["holdout_every"]),
        "--holdout-offset", str(t["holdout_offset"]), "--iterations", str(t["iterations"]),
        "--initial-gaussians", str(t["initial_gaussians"]), "--max-gaussians", str(t["max_gaussians"]),
        "--elevation-sigma", str(t["elevation_sigma"]), "--coarse-fraction", str(t["coarse_fraction"]),
        "--training-cutoff", str(t["training_cutoff"]), "--seed", str(seed), "--threads", str(t["threads"]),
        *(["--refine-poses"] if t["refine_poses"] == 1 else ["--no-refine-poses"] if t["refine_poses"] == 0 else []))
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(field)
    reader.Update()
    trained = reader.GetOutput()
    frames = trained.GetFieldData().GetArray("TrainingFrames")
    training_frames = sorted(int(frames.GetTuple1(k)) for k in range(frames.GetNumberOfTuples()))
    held_out = mean_psnr(bigus_exe, field,
                         ["--holdout-every", str(t["holdout_every"]), "--holdout-offset", str(t["holdout_offset"])])
    training = mean_psnr(bigus_exe, field, ["--frames", *map(str, training_frames)])
    return trained, training_frames, held_out, training


def spread(bigus_exe, seeds):
    values = []
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(1, seeds + 1):
            trained, _, held_out, training = train(bigus_exe, os.path.join(folder, "field.vtp"), seed)
            values.append((held_out, training))
            print("seed %2d  %d Gaussians, held-out PSNR %.4f dB, training PSNR %.4f dB"
                  % (seed, trained.GetNumberOfPoints(), held_out, training))
    for name, column in (("held-out", [v[0] for v in values]), ("training", [v[1] for v in values])):
        mean = sum(column) / len(column)
        std = math.sqrt(sum((x - mean) ** 2 for x in column) / max(1, len(column) - 1))
        print("%-8s PSNR mean %.4f dB, standard deviation %.4f dB, range %.4f .. %.4f"
              % (name, mean, std, min(column), max(column)))


def unit(a):
    n = math.sqrt(sum(x * x for x in a))
    return [x / n for x in a]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def orthogonal(a, b):
    """a minus its component along the unit vector b."""
    d = sum(a[r] * b[r] for r in range(3))
    return [a[r] - d * b[r] for r in range(3)]


def axes_matrix(x, y, z, origin):
    """Row-major 4x4 whose columns are x, y, z and origin (vtkImageReslice's ResliceAxes)."""
    return [x[0], y[0], z[0], origin[0], x[1], y[1], z[1], origin[1], x[2], y[2], z[2], origin[2], 0, 0, 0, 1]


def main():
    bigus_exe = os.path.abspath(sys.argv[1])
    if len(sys.argv) == 4 and sys.argv[2] == "--spread":
        spread(bigus_exe, int(sys.argv[3]))
        return
    sweep = os.path.join(FIXTURE, SWEEP)
    trained, training_frames, held_out, training = train(bigus_exe, os.path.join(HERE, FIELD), TRAINING["seed"])

    reader = bigus.vtkUltrasoundSequenceReader()
    reader.SetFileName(sweep)
    reader.SetCalibrationFileName(os.path.join(FIXTURE, CALIBRATION))
    reader.Update()
    w, h, _ = reader.GetOutput().GetDimensions()
    poses = reader.GetOutput().GetFieldData().GetArray("ImageToReference")

    def frame_axes(k):
        m = poses.GetTuple(k)
        columns = [[m[4 * r + c] for r in range(3)] for c in range(4)]
        spacing = [math.sqrt(sum(x * x for x in columns[c])) for c in range(2)]
        return unit(columns[0]), unit(columns[1]), columns[3], spacing

    pixels = vtk_to_numpy(reader.GetOutput().GetPointData().GetScalars()).reshape(-1, h, w).astype(float)
    fan = bigus.vtkUltrasoundFanMask()
    fan.SetInputConnection(reader.GetOutputPort())
    fan.Update()
    imaged = vtk_to_numpy(fan.GetOutput().GetPointData().GetScalars()).reshape(h, w) != 0

    def frame_axes_at_centroid(k):
        """Unit axes u, v, n of frame k, the point (mm) of the intensity-weighted centroid of its pixels
        inside the fan mask (what the field was trained on), spacing."""
        u, v, origin, spacing = frame_axes(k)
        weights = pixels[k] * imaged
        weights /= weights.sum()
        ic = (weights.sum(axis=0) * range(w)).sum()
        jc = (weights.sum(axis=1) * range(h)).sum()
        centre = [origin[r] + u[r] * spacing[0] * ic + v[r] * spacing[1] * jc for r in range(3)]
        return u, v, unit(cross(u, v)), centre, spacing

    # 1. Training frame 8 at its recorded pose: the pose's own (slightly sheared) axes and spacing.
    u, v, origin, spacing = frame_axes(8)
    planes = [{
        "name": "frame8",
        "image": "nwire_frame8.mha",
        "frame": 8,
        "reslice_axes": axes_matrix(u, v, unit(cross(u, v)), origin),
        "output_spacing": [spacing[0], spacing[1], 1.0],
        "output_origin": [0.0, 0.0, 0.0],
        "output_extent": [0, w - 1, 0, h - 1, 0, 0],
        "output_dimensionality": 2,
    }]
    # 2. An oblique plane no frame saw: through the bright structure of held-out frame 10 (the
    #    intensity-weighted centroid of its imaged pixels), the frame's lateral axis turned 30 degrees towards the
    #    elevation direction (about the depth axis), at the frame's pixel size.
    u, v, n, centre, spacing = frame_axes_at_centroid(10)
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    x = unit(orthogonal([c * u[r] + s * n[r] for r in range(3)], v))
    planes.append({
        "name": "oblique",
        "image": "nwire_oblique.mha",
        "reslice_axes": axes_matrix(x, v, cross(x, v), centre),
        "output_spacing": [spacing[0], spacing[1], 1.0],
        "output_origin": [-0.5 * spacing[0] * (w - 1), -0.5 * spacing[1] * (h - 1), 0.0],
        "output_extent": [0, w - 1, 0, h - 1, 0, 0],
        "output_dimensionality": 2,
    })
    # 3. A stack of 9 parallel slices (OutputDimensionality 3) 0.3 mm apart across the sweep, 8 x 6 mm
    #    at 0.1 mm pixels, centred on the bright structure of held-out frame 14, in that frame's
    #    orthonormalised axes.
    u, v, n, centre, _ = frame_axes_at_centroid(14)
    v = unit(orthogonal(v, u))
    planes.append({
        "name": "stack",
        "image": "nwire_stack.mha",
        "reslice_axes": axes_matrix(u, v, cross(u, v), centre),
        "output_spacing": [0.1, 0.1, 0.3],
        "output_origin": [-3.95, -2.95, -1.2],
        "output_extent": [0, 79, 0, 59, 0, 8],
        "output_dimensionality": 3,
    })
    # 4. The whole field on the default grid of OutputDimensionality 3 (identity axes, the field's padded
    #    bounds) at 0.5 mm voxels: `bigus render --volume --spacing 0.5`; every Gaussian shows somewhere.
    planes.append({
        "name": "volume",
        "image": "nwire_volume.mha",
        "output_spacing": [0.5, 0.5, 0.5],
        "output_dimensionality": 3,
    })

    for plane in planes:
        reslice = bigus.vtkGaussianFieldReslice()
        reslice.SetInputData(trained)
        if "reslice_axes" in plane:
            matrix = vtk.vtkMatrix4x4()
            matrix.DeepCopy(plane["reslice_axes"])
            reslice.SetResliceAxes(matrix)
        reslice.SetOutputSpacing(plane["output_spacing"])
        if "output_origin" in plane:
            reslice.SetOutputOrigin(plane["output_origin"])
        if "output_extent" in plane:
            reslice.SetOutputExtent(plane["output_extent"])
        reslice.SetOutputDimensionality(plane["output_dimensionality"])
        reslice.Update()
        image = reslice.GetOutput()
        if image.GetNumberOfPoints() == 0:
            sys.exit("rendering %s failed" % plane["name"])
        writer = vtk.vtkMetaImageWriter()
        writer.SetInputData(image)
        writer.SetFileName(os.path.join(HERE, plane["image"]))
        writer.SetCompression(True)
        writer.Write()
        print("%-8s %s x %s x %s, intensity %.4f .. %.4f" % (plane["name"], *image.GetDimensions(),
                                                             *image.GetScalarRange()))

    reference = {
        "generator": "Testing/Data/Reference/make_reference.py",
        "sweep": "nwire-phantom/" + SWEEP,
        "calibration": "nwire-phantom/" + CALIBRATION,
        "field": FIELD,
        "number_of_gaussians": trained.GetNumberOfPoints(),
        "training": dict(TRAINING, training_frames=training_frames, held_out_psnr=held_out, training_psnr=training),
        "planes": planes,
    }
    with open(os.path.join(HERE, "reference.json"), "w") as f:
        json.dump(reference, f, indent=2)
        f.write("\n")
    print("field    %d Gaussians, held-out PSNR %.4f dB, training PSNR %.4f dB"
          % (trained.GetNumberOfPoints(), held_out, training))


if __name__ == "__main__":
    main()

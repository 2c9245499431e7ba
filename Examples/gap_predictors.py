"""How well can any view of a gap be predicted from the two recorded frames that bracket it?

The block hold-outs of `bigus benchmark --section blocks` hold out 8 or 20 consecutive liver frames
(66 to 73, 60 to 79) and compare BIGUS with the blend of the bracketing frames in time. This script
scores, on the same frames and fan mask (PSNR in dB, data range 1, inside the mask, as the benchmark):
- the blend (1 - t) A + t B, t from the timestamps (the benchmark's baseline);
- the blend shrunk towards its local mean, L + a (blend - L) with L the blend under a masked Gaussian
  of s pixels: the conditional mean when the speckle of A and B does not correlate with the gap's;
- a morph: A and B displaced along a displacement field found by block matching (patches of P pixels,
  search radius R pixels, on images smoothed by a Gaussian of S pixels; a 3 x 3 median of the patch
  displacements, bilinear between patch centres), A moved by t d and B by (1 - t) d: what a structure
  crossing the gap obliquely would need.
Only numpy and the project's Python module. Usage (after ./setup.sh build):
  PYTHONPATH=build/lib/python3/dist-packages python3 Examples/gap_predictors.py
"""
import argparse
import math
import os

import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy

import bigus

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def masked_psnr(a, b, mask):
    mse = float(np.mean((a[mask] - b[mask]) ** 2))
    return 10 * math.log10(1.0 / mse) if mse > 0 else 100.0


def blur(image, sigma):
    """Separable Gaussian (taps to 4 sigma), borders reflected."""
    radius = max(1, int(math.ceil(4 * sigma)))
    x = np.arange(-radius, radius + 1)
    kernel = np.exp(-x ** 2 / (2 * sigma ** 2))
    kernel /= kernel.sum()
    out = np.pad(image, radius, mode="symmetric")
    out = sum(k * out[:, i:i + image.shape[1]] for i, k in enumerate(kernel))[radius:-radius]
    out2 = np.pad(out, ((radius, radius), (0, 0)), mode="symmetric")
    return sum(k * out2[i:i + image.shape[0]] for i, k in enumerate(kernel))


def bilinear(image, y, x):
    """image sampled at (y, x) (pixels), bilinear, clamped to the border."""
    h, w = image.shape
    y = np.clip(y, 0, h - 1.000001)
    x = np.clip(x, 0, w - 1.000001)
    y0, x0 = np.floor(y).astype(int), np.floor(x).astype(int)
    fy, fx = y - y0, x - x0
    return ((1 - fy) * ((1 - fx) * image[y0, x0] + fx * image[y0, x0 + 1]) +
            fy * ((1 - fx) * image[y0 + 1, x0] + fx * image[y0 + 1, x0 + 1]))


def displacement(a, b, mask, patch, radius, smooth):
    """Dense (dy, dx) with a(p) ~ b(p + d), by block matching (sum of squared differences)."""
    h, w = a.shape
    sa, sb = blur(a, smooth), blur(b, smooth)
    step = patch // 2
    gy = np.arange(radius, h - patch - radius, step)
    gx = np.arange(radius, w - patch - radius, step)
    d = np.zeros((len(gy), len(gx), 2))
    for i, y in enumerate(gy):
        for j, x in enumerate(gx):
            if mask[y:y + patch, x:x + patch].mean() < 0.5:
                continue
            ref = sa[y:y + patch, x:x + patch]
            errors = [(np.sum((ref - sb[y + dy:y + dy + patch, x + dx:x + dx + patch]) ** 2), dy, dx)
                      for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)]
            d[i, j] = min(errors)[1:]
    padded = np.pad(d, ((1, 1), (1, 1), (0, 0)), mode="edge")
    d = np.median(np.stack([padded[i:i + d.shape[0], j:j + d.shape[1]] for i in range(3) for j in range(3)]), axis=0)
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    cy = np.clip((yy - radius - patch / 2) / step, 0, len(gy) - 1)
    cx = np.clip((xx - radius - patch / 2) / step, 0, len(gx) - 1)
    return bilinear(d[:, :, 0], cy, cx), bilinear(d[:, :, 1], cy, cx)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sweep", default=os.path.join(ROOT, "Examples", "Data", "liver", "liver_sweep.igs.mha"))
    parser.add_argument("--patch", type=int, default=64)
    parser.add_argument("--radius", type=int, default=4)
    parser.add_argument("--smooth", type=float, default=3.0)
    args = parser.parse_args()
    reader = bigus.vtkUltrasoundSequenceReader()
    reader.SetFileName(args.sweep)
    fan = bigus.vtkUltrasoundFanMask()
    fan.SetInputConnection(reader.GetOutputPort())
    fan.Update()
    image = reader.GetOutput()
    w, h, n = image.GetDimensions()
    frames = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(n, h, w).astype(np.float64) / 255
    mask = vtk_to_numpy(fan.GetOutput().GetPointData().GetScalars()).reshape(h, w) != 0
    stamps = vtk_to_numpy(image.GetFieldData().GetArray("Timestamp"))
    scales = (1.0, 2.0, 4.0)
    mask_weights = {s: np.maximum(blur(mask.astype(float), s), 1e-6) for s in scales}  # the local means' normalisers
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    for block in (range(66, 74), range(60, 80)):
        before, after = block[0] - 1, block[-1] + 1
        a, b = frames[before], frames[after]
        dy, dx = displacement(a, b, mask, args.patch, args.radius, args.smooth)
        scores = {}
        for k in block:
            t = (stamps[k] - stamps[before]) / (stamps[after] - stamps[before])
            blend = (1 - t) * a + t * b
            scores.setdefault("blend", []).append(masked_psnr(blend, frames[k], mask))
            for s in scales:
                local = blur(blend * mask, s) / mask_weights[s]
                for shrink in (0.5, 0.75):
                    key = "shrunk, s %.0f px, a %.2f" % (s, shrink)
                    scores.setdefault(key, []).append(masked_psnr(local + shrink * (blend - local), frames[k], mask))
            morph = (1 - t) * bilinear(a, yy - t * dy, xx - t * dx) + t * bilinear(b, yy + (1 - t) * dy, xx + (1 - t) * dx)
            scores.setdefault("morph", []).append(masked_psnr(morph, frames[k], mask))
        print("frames %d to %d held out (%d); displacement mean %.2f px, largest %.1f px" % (
            block[0], block[-1], len(block), np.mean(np.hypot(dy, dx)[mask]), np.max(np.hypot(dy, dx)[mask])))
        for key, values in scores.items():
            print("  %-28s %.2f dB" % (key, np.mean(values)))


if __name__ == "__main__":
    main()

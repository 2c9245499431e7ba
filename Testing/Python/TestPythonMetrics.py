"""/usr/bin/python3 runs bigus.vtkUltrasoundImageMetrics on sequences built with numpy and checks the
table against PSNR and NCC computed here with numpy.

Usage: TestPythonMetrics.py TESTING_DATA_DIR EXAMPLE_DATA_DIR
"""
import math

import numpy as np
import vtk
from vtk.util import numpy_support

import bigus

W, H, N = 96, 72, 4


def sequence(frames, frame_index=None, frame_valid=None):
    """W x H x N vtkImageData from an [N, H, W] array (x fastest, as VTK stores it)."""
    image = vtk.vtkImageData()
    image.SetDimensions(frames.shape[2], frames.shape[1], frames.shape[0])
    scalars = numpy_support.numpy_to_vtk(np.ascontiguousarray(frames).ravel(), deep=True)
    scalars.SetName("Intensity")
    image.GetPointData().SetScalars(scalars)
    if frame_index is not None:
        array = numpy_support.numpy_to_vtk(np.asarray(frame_index, dtype=np.int32), deep=True)
        array.SetName("FrameIndex")
        image.GetFieldData().AddArray(array)
    if frame_valid is not None:
        array = numpy_support.numpy_to_vtk(np.asarray(frame_valid, dtype=np.uint8), deep=True)
        array.SetName("FrameValid")
        image.GetFieldData().AddArray(array)
    return image


def column(table, name):
    array = table.GetColumnByName(name)
    assert array is not None, name
    return [array.GetValue(r) for r in range(array.GetNumberOfTuples())]


def expected_metrics(rendered, truth, mask):
    """PSNR (data range 1) and Pearson correlation of the masked pixels of each frame."""
    psnr, ncc = [], []
    for a, b in zip(rendered, truth):
        a, b = a[mask].astype(np.float64), b[mask].astype(np.float64)
        psnr.append(10 * math.log10(1.0 / np.mean((a - b) ** 2)))
        ncc.append(np.corrcoef(a, b)[0, 1])
    return psnr, ncc


def main():
    rng = np.random.default_rng(3)
    # Truth: 8-bit speckle-like frames (Rayleigh amplitude); rendered: float32 in [0, 1] with noise.
    truth = np.clip(rng.rayleigh(50.0, size=(N, H, W)), 0, 255).astype(np.uint8)
    noise = rng.normal(0.0, 0.03 * (1 + np.arange(N)), size=(W, H, N)).T.astype(np.float32)
    rendered = np.clip(truth.astype(np.float32) / 255 + noise, 0, 1).astype(np.float32)
    truth_float = truth.astype(np.float32) / 255

    yy, xx = np.mgrid[0:H, 0:W]
    mask = ((xx - W / 2) ** 2 / (0.45 * W) ** 2 + (yy - H / 2) ** 2 / (0.45 * H) ** 2) <= 1
    mask_image = vtk.vtkImageData()
    mask_image.SetDimensions(W, H, 1)
    mask_scalars = numpy_support.numpy_to_vtk(mask.astype(np.uint8).ravel(), deep=True)
    mask_scalars.SetName("FanMask")
    mask_image.GetPointData().SetScalars(mask_scalars)

    index = [10, 11, 12, 13]
    metrics = bigus.vtkUltrasoundImageMetrics()
    metrics.SetInputData(0, sequence(rendered))
    metrics.SetTruthData(sequence(truth, frame_index=index, frame_valid=[1, 1, 1, 1]))
    for use_mask in (False, True):
        metrics.SetMaskData(mask_image if use_mask else None)
        metrics.Update()
        table = metrics.GetOutput()
        assert table.GetNumberOfRows() == N + 1, table.GetNumberOfRows()
        assert column(table, "Frame") == index + [-1], column(table, "Frame")
        psnr, ncc = expected_metrics(rendered, truth_float, mask if use_mask else np.ones((H, W), bool))
        got_psnr, got_ncc = column(table, "PSNR"), column(table, "NCC")
        for k in range(N):
            assert abs(got_psnr[k] - psnr[k]) < 1e-4, (use_mask, k, got_psnr[k], psnr[k])
            assert abs(got_ncc[k] - ncc[k]) < 1e-6, (use_mask, k, got_ncc[k], ncc[k])
        assert got_psnr == sorted(got_psnr[:N], reverse=True) + [got_psnr[N]], got_psnr  # more noise, lower PSNR
        assert abs(got_psnr[N] - np.mean(psnr)) < 1e-4 and abs(metrics.GetMeanPSNR() - np.mean(psnr)) < 1e-4
        assert abs(got_ncc[N] - np.mean(ncc)) < 1e-6 and abs(metrics.GetMeanNCC() - np.mean(ncc)) < 1e-6
        ssim = column(table, "SSIM")
        assert all(0 < s < 1 for s in ssim), ssim
        print("mask" if use_mask else "no mask", "PSNR", np.round(got_psnr, 3), "NCC", np.round(got_ncc, 4),
              "SSIM", np.round(ssim, 4), "Speckle", np.round(column(table, "Speckle"), 4))

    # An invalid truth frame gets no row.
    metrics.SetTruthData(sequence(truth, frame_index=index, frame_valid=[1, 0, 1, 1]))
    metrics.Update()
    assert column(metrics.GetOutput(), "Frame") == [10, 12, 13, -1], column(metrics.GetOutput(), "Frame")

    # Rendered frames identical to the truth: the PSNR cap and perfect scores.
    metrics.SetInputData(0, sequence(truth))
    metrics.Update()
    assert metrics.GetMeanPSNR() == 100.0
    assert abs(metrics.GetMeanSSIM() - 1) < 1e-12 and abs(metrics.GetMeanNCC() - 1) < 1e-12
    assert abs(metrics.GetMeanSpeckle() - 1) < 1e-12
    print("vtkUltrasoundImageMetrics from Python agrees with numpy's PSNR and NCC")


if __name__ == "__main__":
    main()

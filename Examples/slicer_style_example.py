"""Python example in the style of a 3D Slicer script: read a tracked sweep, train a field with a small
budget, reslice a plane given by a vtkMatrix4x4, write the slice, and cut the rendered volume with
vtkImageReslice (as Slicer would any volume).

    /usr/bin/python3 slicer_style_example.py SWEEP CALIBRATION_XML OUTPUT_DIR [ITERATIONS]
"""
import os
import sys

import vtk
import bigus


def main():
    sweep, calibration, out = sys.argv[1:4]
    iterations = int(sys.argv[4]) if len(sys.argv) > 4 else 300
    os.makedirs(out, exist_ok=True)

    reader = bigus.vtkUltrasoundSequenceReader()
    reader.SetFileName(sweep)
    reader.SetCalibrationFileName(calibration)
    reader.Update()
    if reader.GetLastErrorText():
        sys.exit(reader.GetLastErrorText())

    trainer = bigus.vtkGaussianFieldTrainer()
    trainer.SetInputConnection(reader.GetOutputPort())
    trainer.SetIterations(iterations)
    trainer.SetElevationSigma(1.0)
    trainer.Update()
    print("trained", trainer.GetNumberOfGaussians(), "Gaussians:", trainer.GetStopReason())

    # The plane of the middle frame, as a vtkMatrix4x4 (columns: x axis, y axis, normal, origin).
    frames = reader.GetOutput()
    middle = frames.GetDimensions()[2] // 2
    pose = frames.GetFieldData().GetArray("ImageToReference").GetTuple(middle)
    axes = vtk.vtkMatrix4x4()
    geometry = bigus.vtkUltrasoundSliceGeometry()
    matrix = vtk.vtkMatrix4x4()
    matrix.DeepCopy(pose)
    geometry.SetImageToReference(matrix)
    for column, vector in enumerate((geometry.GetAxisU(), geometry.GetAxisV(), geometry.GetNormal(),
                                     geometry.GetOrigin())):
        for row in range(3):
            axes.SetElement(row, column, vector[row])

    reslice = bigus.vtkGaussianFieldReslice()
    reslice.SetInputConnection(trainer.GetOutputPort())
    reslice.SetResliceAxes(axes)
    spacing = geometry.GetPixelSpacing()
    width, height = frames.GetDimensions()[:2]
    reslice.SetOutputSpacing(spacing[0], spacing[1], 1.0)
    reslice.SetOutputOrigin(0, 0, 0)
    reslice.SetOutputExtent(0, width - 1, 0, height - 1, 0, 0)
    reslice.SetOutputScalarTypeToUnsignedChar()
    png = vtk.vtkPNGWriter()
    png.SetInputConnection(reslice.GetOutputPort())
    png.SetFileName(os.path.join(out, "middle_frame_plane.png"))
    png.Write()

    # A volume (stack of parallel slices) cut by vtkImageReslice.
    volume = bigus.vtkGaussianFieldReslice()
    volume.SetInputConnection(trainer.GetOutputPort())
    volume.SetOutputDimensionality(3)
    volume.SetOutputSpacing(1.0, 1.0, 1.0)
    volume.Update()
    cut = vtk.vtkImageReslice()
    cut.SetInputConnection(volume.GetOutputPort())
    cut.SetOutputDimensionality(2)
    center = volume.GetOutput().GetCenter()
    cut.SetResliceAxesOrigin(center)
    cut.Update()
    print("volume", volume.GetOutput().GetDimensions(), "cut", cut.GetOutput().GetDimensions()[:2])
    assert cut.GetOutput().GetNumberOfPoints() > 0


if __name__ == "__main__":
    main()

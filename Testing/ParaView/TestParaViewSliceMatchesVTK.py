"""/usr/bin/python3 with the VTK build: the ParaView plugin's slice equals vtkGaussianFieldReslice's.

Usage: TestParaViewSliceMatchesVTK.py OUTPUT_DIR   (after TestParaViewPlugin.py wrote into OUTPUT_DIR)

Reads the field that ParaView trained and wrote (paraview_field.vtp), the plane it sliced
(paraview_plane.json: origin, normal, spacing, dimensions) and its slice (paraview_slice.vti). Builds
the reslice axes from the plane here, independently of the plugin's C++ (normal n = normal / |normal|;
x axis = the world axis least aligned with n, X first on a tie, projected onto the plane; y = n x x;
the grid centred on the origin), checks that the plugin placed the slice there in the world (origin
and direction matrix), renders them with the VTK build's vtkGaussianFieldReslice, and
requires every pixel to agree to float rounding (1e-6; intensities lie in [0, 1]). The two builds
compile the same sources against VTK 9.1 and ParaView's VTK 9.2.
"""
import json
import math
import os
import sys

import vtk
import bigus


def plane_axes(origin, normal):
    length = math.sqrt(sum(c * c for c in normal))
    n = [c / length for c in normal]
    least = min(range(3), key=lambda k: (abs(n[k]), k))
    x = [1.0 if k == least else 0.0 for k in range(3)]
    along = sum(a * b for a, b in zip(x, n))
    x = [a - along * b for a, b in zip(x, n)]
    norm = math.sqrt(sum(c * c for c in x))
    x = [c / norm for c in x]
    y = [n[1] * x[2] - n[2] * x[1], n[2] * x[0] - n[0] * x[2], n[0] * x[1] - n[1] * x[0]]
    axes = vtk.vtkMatrix4x4()
    for r in range(3):
        axes.SetElement(r, 0, x[r])
        axes.SetElement(r, 1, y[r])
        axes.SetElement(r, 2, n[r])
        axes.SetElement(r, 3, origin[r])
    return axes


def main():
    folder = sys.argv[1]
    with open(os.path.join(folder, "paraview_plane.json")) as f:
        plane = json.load(f)
    field = vtk.vtkXMLPolyDataReader()
    field.SetFileName(os.path.join(folder, "paraview_field.vtp"))
    field.Update()
    assert field.GetOutput().GetNumberOfPoints() > 100, "the field ParaView wrote is empty"
    theirs = vtk.vtkXMLImageDataReader()
    theirs.SetFileName(os.path.join(folder, "paraview_slice.vti"))
    theirs.Update()

    reslice = bigus.vtkGaussianFieldReslice()
    reslice.SetInputConnection(field.GetOutputPort())
    axes = plane_axes(plane["origin"], plane["normal"])
    reslice.SetResliceAxes(axes)
    nx, ny = plane["dimensions"][:2]
    sx, sy = plane["spacing"][:2]
    reslice.SetOutputSpacing(sx, sy, 1.0)
    reslice.SetOutputOrigin(-0.5 * (nx - 1) * sx, -0.5 * (ny - 1) * sy, 0.0)
    reslice.SetOutputExtent(0, nx - 1, 0, ny - 1, 0, 0)
    reslice.Update()
    ours = reslice.GetOutput()

    a, b = theirs.GetOutput(), ours
    assert a.GetDimensions() == b.GetDimensions(), (a.GetDimensions(), b.GetDimensions())
    # The plugin places the slice in the world (origin = axes * grid origin, direction = the axes'
    # rotation); vtkGaussianFieldReslice leaves it in the reslice frame, as vtkImageReslice does.
    world = axes.MultiplyPoint(list(b.GetOrigin()) + [1.0])[:3]
    direction = a.GetDirectionMatrix()
    for k in range(3):
        assert abs(a.GetSpacing()[k] - b.GetSpacing()[k]) < 1e-12, (a.GetSpacing(), b.GetSpacing())
        assert abs(a.GetOrigin()[k] - world[k]) < 1e-9, (a.GetOrigin(), world)
        for c in range(3):
            assert abs(direction.GetElement(k, c) - axes.GetElement(k, c)) < 1e-12, (k, c)
    worst, nonzero = 0.0, 0
    pa, pb = a.GetPointData().GetArray("Intensity"), b.GetPointData().GetArray("Intensity")
    assert pa.GetNumberOfTuples() == pb.GetNumberOfTuples() == nx * ny
    for i in range(pa.GetNumberOfTuples()):
        worst = max(worst, abs(pa.GetValue(i) - pb.GetValue(i)))
        nonzero += pb.GetValue(i) > 0.01
    print("%d pixels, %d above 0.01, largest difference %.3g" % (pa.GetNumberOfTuples(), nonzero, worst))
    # The N-wire phantom is dark but for its wires and the membrane: about 3 % of this slice is lit.
    assert nonzero > 0.01 * nx * ny, "the slice is almost empty: the comparison would prove little"
    assert worst <= 1e-6, "ParaView's slice differs from the VTK build's by %g" % worst
    print("ok")


if __name__ == "__main__":
    main()

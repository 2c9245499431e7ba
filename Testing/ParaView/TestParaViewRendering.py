"""pvbatch (needs a display: run under xvfb-run -a): ParaView renders a BIGUS slice and volume as before.

Usage: pvbatch TestParaViewRendering.py PLUGIN TEST_DATA_DIR OUTPUT_DIR [--shift MM]

Reads the committed field Testing/Data/Reference/nwire_reference.vtp with ParaView's own XML reader,
renders (1) a slice of it with the plugin's slice filter through the centre of the oblique plane of
Testing/Data/Reference/reference.json (turned 30 degrees from the frames) and parallel to it, shown in
a render view, and (2) a stack of slices (OutputDimensionality 3) around it, volume-rendered, saves both screenshots to OUTPUT_DIR
and compares each with its baseline in TEST_DATA_DIR/Baseline (ParaViewSlice.png, ParaViewVolume.png)
with VTK's image comparison (vtkTesting::RegressionTest with vtkRegressionTestImage's threshold,
0.15). --shift MM moves the slice's plane MM along its normal (new content) and draws the volume MM
off along the plane's x axis (a misplaced volume; its content lies in the world, so moving its grid
would not change the picture): both must fail the comparison. The colour map is black-body (black, red, yellow, white): VTK's comparison forgives small
grey-level changes, and on a grey ramp it missed a 0.5 mm shift of the plane. Exits 125
(skipped) without a display. A missing baseline is written from the screenshot (and the test fails),
which is how the baselines were made.
"""
import json
import os
import shutil
import sys

if not os.environ.get("DISPLAY"):
    print("no DISPLAY: skipped")
    sys.exit(125)

import paraview.simple as pvs
from vtkmodules.vtkTestingRendering import vtkTesting

THRESHOLD = 0.15  # vtkRegressionTestImage's in VTK 9.1 and 9.2


def compare(view, name, baselines, output):
    png = os.path.join(output, name)
    pvs.SaveScreenshot(png, view, ImageResolution=[300, 225])
    baseline = os.path.join(baselines, name)
    if not os.path.exists(baseline):
        shutil.copyfile(png, baseline)
        print("%s: no baseline, wrote %s from the screenshot" % (name, baseline))
        return False
    testing = vtkTesting()
    for argument in ("-V", baseline, "-T", output):
        testing.AddArgument(argument)
    passed = testing.RegressionTest(png, THRESHOLD) == vtkTesting.PASSED
    print("%s: image difference %.3f (threshold %g): %s" % (name, testing.GetImageDifference(), THRESHOLD,
                                                           "passed" if passed else "FAILED"))
    return passed


def main():
    plugin, data, output = (os.path.abspath(a) for a in sys.argv[1:4])  # vtkTesting reads -V relative to -D
    shift = float(sys.argv[5]) if len(sys.argv) > 5 and sys.argv[4] == "--shift" else 0.0
    os.makedirs(output, exist_ok=True)
    pvs.LoadPlugin(plugin)  # adds the plugin's readers and filters to paraview.simple
    field = pvs.XMLPolyDataReader(FileName=[os.path.join(data, "Reference", "nwire_reference.vtp")])
    with open(os.path.join(data, "Reference", "reference.json")) as f:
        oblique = next(p for p in json.load(f)["planes"] if p["name"] == "oblique")
    axes = oblique["reslice_axes"]  # row-major 4 x 4: columns x, y, normal, origin (mm)
    column = [[axes[4 * r + c] for r in range(3)] for c in range(4)]
    middle = [oblique["output_origin"][k] + 0.5 * oblique["output_extent"][2 * k + 1] * oblique["output_spacing"][k]
              for k in range(2)]
    normal = column[2]
    centre = [column[3][r] + middle[0] * column[0][r] + middle[1] * column[1][r] for r in range(3)]
    origin = [centre[r] + shift * normal[r] for r in range(3)]

    view = pvs.CreateView("RenderView")
    view.ViewSize = [300, 225]
    view.OrientationAxesVisibility = 0
    view.Background = [0.1, 0.1, 0.15]
    try:
        view.UseColorPaletteForBackground = 0
    except AttributeError:
        pass
    lut = pvs.GetColorTransferFunction("Intensity")
    lut.ApplyPreset("Black-Body Radiation", True)
    lut.RescaleTransferFunction(0.0, 1.0)
    lut.AutomaticRescaleRangeMode = "Never"

    # The field's default look in ParaView: points coloured by reflectivity (its active scalars).
    points = pvs.Show(field, view)
    look = (points.Representation, list(points.ColorArrayName))
    print("the field shows as %s coloured by %s" % (look[0], look[1][1]))
    if look[1][1] != "Reflectivity":
        print("FAILED: the field is not coloured by Reflectivity by default")
        sys.stdout.flush()
        os._exit(1)
    pvs.Hide(field, view)

    slice_filter = pvs.GaussianFieldSlice(Input=field, SliceOrigin=origin, SliceNormal=normal,
                                          SliceSpacing=[0.08, 0.08, 1.0], SliceDimensions=[200, 150, 1])
    shown = pvs.Show(slice_filter, view)
    shown.Representation = "Slice"
    pvs.ColorBy(shown, ("POINTS", "Intensity"))
    shown.LookupTable = lut
    view.CameraPosition = [centre[k] + 60 * normal[k] for k in range(3)]
    view.CameraFocalPoint = centre
    view.CameraViewUp = [-c for c in column[1]]
    view.CameraParallelProjection = 1
    view.CameraParallelScale = 6.5
    pvs.Render(view)
    passed = compare(view, "ParaViewSlice.png", os.path.join(data, "Baseline"), output)
    pvs.Hide(slice_filter, view)

    stack = pvs.GaussianFieldSlice(Input=field, SliceOrigin=centre, SliceNormal=normal,
                                   SliceSpacing=[0.5, 0.5, 0.5], SliceDimensions=[48, 36, 28],
                                   OutputDimensionality=3)
    volume = pvs.Show(stack, view)
    volume.Representation = "Volume"
    pvs.ColorBy(volume, ("POINTS", "Intensity"))
    volume.LookupTable = lut
    opacity = pvs.GetOpacityTransferFunction("Intensity")
    opacity.Points = [0.0, 0.0, 0.5, 0.0, 0.05, 0.0, 0.5, 0.0, 0.4, 1.0, 0.5, 0.0, 1.0, 1.0, 0.5, 0.0]
    volume.ScalarOpacityFunction = opacity
    volume.Position = [shift * c for c in column[0]]
    view.CameraPosition = [centre[r] + 40 * normal[r] + 25 * column[0][r] - 20 * column[1][r] for r in range(3)]
    view.CameraFocalPoint = centre
    view.CameraViewUp = [-c for c in column[1]]
    view.CameraParallelProjection = 0
    view.CameraViewAngle = 30
    pvs.Render(view)
    passed = compare(view, "ParaViewVolume.png", os.path.join(data, "Baseline"), output) and passed
    # Leave without ParaView's teardown: under Xvfb it ends in a GLXBadContext X error and exit code 1
    # after every image was compared.
    sys.stdout.flush()
    os._exit(0 if passed else 1)


if __name__ == "__main__":
    main()

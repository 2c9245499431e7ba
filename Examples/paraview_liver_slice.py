"""ParaView example (pvpython or pvbatch): read the bundled liver sweep, train briefly, save a slice.

    pvbatch Examples/paraview_liver_slice.py [--plugin BIGUS.so] [--seconds 20] [--output liver_slice.png]

Loads the BIGUS plugin (--plugin, or ParaView loads it at start from PV_PLUGIN_PATH), reads
Examples/Data/liver/liver_sweep.igs.mha with the plugin's reader (its ImageToReference poses need no
calibration file), trains a Gaussian field for --seconds with the trainer's defaults, slices it with
an oblique plane through the middle of the sweep (the plane a ParaView user drags with the widget),
shows the slice in grey levels, and saves a screenshot. Rendering needs a display: run it
under `xvfb-run -a` on a machine without one.
"""
import argparse
import os
import sys

import paraview.simple as pvs

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plugin", help="the plugin file BIGUS.so (default: loaded from PV_PLUGIN_PATH)")
    parser.add_argument("--sweep", default=os.path.join(HERE, "Data", "liver", "liver_sweep.igs.mha"))
    parser.add_argument("--seconds", type=float, default=20.0, help="training time budget (s)")
    parser.add_argument("--output", default="liver_slice.png", help="screenshot (PNG)")
    args = parser.parse_args()
    if not os.environ.get("DISPLAY"):
        print("no DISPLAY: rendering needs one (run under xvfb-run -a)")
        sys.exit(125)

    if args.plugin:
        pvs.LoadPlugin(args.plugin)
    if not hasattr(pvs, "TrainGaussianField"):
        raise SystemExit("the BIGUS plugin is not loaded: give --plugin PATH/BIGUS.so or set PV_PLUGIN_PATH")
    sweep = pvs.TrackedUltrasoundSequenceReader(FileName=args.sweep)
    field = pvs.TrainGaussianField(Input=sweep, TimeBudget=args.seconds, Iterations=100000000)
    field.UpdatePipeline()
    print("trained %d Gaussians" % field.GetDataInformation().GetNumberOfPoints())

    bounds = field.GetDataInformation().GetBounds()
    centre = [0.5 * (bounds[2 * k] + bounds[2 * k + 1]) for k in range(3)]
    plane = pvs.GaussianFieldSlice(Input=field, SliceOrigin=centre, SliceNormal=[0.3, 0.2, 1.0],
                                   SliceSpacing=[0.3, 0.3, 1.0])
    view = pvs.GetActiveViewOrCreate("RenderView")
    view.ViewSize = [800, 600]
    shown = pvs.Show(plane, view)
    shown.Representation = "Slice"
    pvs.ColorBy(shown, ("POINTS", "Intensity"))
    lut = pvs.GetColorTransferFunction("Intensity")
    lut.ApplyPreset("Grayscale", True)
    plane.UpdatePipeline()
    lut.RescaleTransferFunction(0.0, max(plane.PointData["Intensity"].GetRange()[1], 1e-3))
    view.CameraFocalPoint = centre
    view.CameraPosition = [c + 500 * n for c, n in zip(centre, plane.SliceNormal)]  # looking along the normal
    view.ResetCamera()
    pvs.Render(view)
    pvs.SaveScreenshot(args.output, view)
    print("wrote " + args.output)
    os._exit(0)  # skip ParaView's teardown, which ends in a GLX error under Xvfb


if __name__ == "__main__":
    main()

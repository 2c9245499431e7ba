"""vtkImageReslice's contract on a Gaussian field (issue 57): each case runs twice, once on a voxel volume through
vtkImageReslice and once on the field the volume was rendered from through vtkGaussianFieldReslice, and asserts the
same output geometry; where the samples lie on the volume's voxels, the same values.

The volume V is the field rendered by vtkGaussianFieldReslice on a 0.5 mm grid with a thin beam (ElevationSigma
1e-4 mm), so that a sample of the field does not depend on the orientation of the slice it is rendered in: resliced by
vtkImageReslice at V's voxels (nearest neighbour), V's values are the field's at the same points. The field side takes
V as its InformationInput, which stands for vtkImageReslice's input: the defaults come from its geometry.

    /usr/bin/python3 TestResliceContract.py [ignored data folders...]
"""
import math
import random
import sys

import vtk
import bigus

FAILURES = []


def check(condition, what):
    if not condition:
        FAILURES.append(what)
        print("FAIL:", what)


def make_field(count=60, seed=3):
    """A field of `count` Gaussians in [1, 9]^3 mm (DESIGN section 2: Scale, Rotation, Reflectivity)."""
    rng = random.Random(seed)
    points = vtk.vtkPoints()
    scale = vtk.vtkFloatArray()
    scale.SetName("Scale")
    scale.SetNumberOfComponents(3)
    rotation = vtk.vtkFloatArray()
    rotation.SetName("Rotation")
    rotation.SetNumberOfComponents(4)
    reflectivity = vtk.vtkFloatArray()
    reflectivity.SetName("Reflectivity")
    for _ in range(count):
        points.InsertNextPoint(rng.uniform(1, 9), rng.uniform(1, 9), rng.uniform(1, 9))
        scale.InsertNextTuple3(rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.9))
        q = [rng.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(v * v for v in q))
        rotation.InsertNextTuple4(*(v / n for v in q))
        reflectivity.InsertNextValue(rng.uniform(0.5, 1.5))
    field = vtk.vtkPolyData()
    field.SetPoints(points)
    for array in (scale, rotation, reflectivity):
        field.GetPointData().AddArray(array)
    for name, value in (("Gamma", 1.0), ("ElevationSigma", 1e-4), ("PixelSpacing", 0.5)):
        a = vtk.vtkDoubleArray()
        a.SetName(name)
        a.InsertNextValue(value)
        field.GetFieldData().AddArray(a)
    return field


FIELD = make_field()


def field_reslice():
    r = bigus.vtkGaussianFieldReslice()
    r.SetInputData(FIELD)
    r.SetElevationSigma(1e-4)
    return r


def render_volume():
    r = field_reslice()
    r.SetOutputDimensionality(3)
    r.SetOutputSpacing(0.5, 0.5, 0.5)
    r.SetOutputOrigin(-0.5, 0.0, 0.5)
    r.SetOutputExtent(0, 22, 0, 20, 0, 18)
    r.Update()
    volume = vtk.vtkImageData()
    volume.DeepCopy(r.GetOutput())
    return volume


V = render_volume()


def geometry(image):
    return image.GetExtent(), image.GetSpacing(), image.GetOrigin()


def same_geometry(a, b, what):
    (ea, sa, oa), (eb, sb, ob) = geometry(a), geometry(b)
    ok = ea == eb and all(abs(x - y) < 1e-9 for x, y in zip(sa, sb)) and all(abs(x - y) < 1e-9 for x, y in zip(oa, ob))
    check(ok, f"{what}: geometry vtkImageReslice {ea} {sa} {oa}, field {eb} {sb} {ob}")


def values(image):
    scalars = image.GetPointData().GetScalars()
    return [scalars.GetTuple1(i) for i in range(scalars.GetNumberOfTuples())]


def largest_difference(a, b):
    va, vb = values(a), values(b)
    if len(va) != len(vb):
        return float("inf")
    return max((abs(x - y) for x, y in zip(va, vb)), default=0.0)


def both(setup, dimensionality=3, information=None):
    """vtkImageReslice on V and vtkGaussianFieldReslice on the field (V as InformationInput), each set up by
    `setup`; `information` is a second image given to both as InformationInput."""
    a = vtk.vtkImageReslice()
    a.SetInputData(V)
    a.SetInterpolationModeToNearestNeighbor()
    b = field_reslice()
    b.SetInformationInput(information if information is not None else V)
    if information is not None:
        a.SetInformationInput(information)
    for r in (a, b):
        r.SetOutputDimensionality(dimensionality)
        setup(r)
        r.Update()
    return a.GetOutput(), b.GetOutput()


def permutations():
    """The 48 axis permutations with sign flips that keep a right-handed frame, as direction cosines."""
    import itertools
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            axes = [[0.0] * 3 for _ in range(3)]
            for column, (row, sign) in enumerate(zip(order, signs)):
                axes[column][row] = float(sign)
            x, y, z = axes
            cross = (x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0])
            if all(abs(c - zc) < 1e-12 for c, zc in zip(cross, z)):
                yield x + y + z


def test_options_and_defaults():
    c, s = math.cos(0.3), math.sin(0.3)
    rotation = (c, s, 0, -s, c, 0, 0, 0, 1)
    cases = [
        ("default", lambda r: None, 3),
        ("OutputDimensionality 2", lambda r: None, 2),
        ("OutputDimensionality 1", lambda r: None, 1),
        ("OutputDimensionality 2, origin set", lambda r: r.SetOutputOrigin(1, 2, 3), 2),
        ("spacing set", lambda r: r.SetOutputSpacing(1, 1, 1), 3),
        ("spacing set then default", lambda r: (r.SetOutputSpacing(1, 1, 1), r.SetOutputSpacingToDefault()), 3),
        ("extent set", lambda r: r.SetOutputExtent(2, 10, -3, 4, 0, 5), 3),
        ("origin set", lambda r: r.SetOutputOrigin(-2, 1.5, 4), 3),
        ("rotated axes", lambda r: r.SetResliceAxesDirectionCosines(*rotation), 3),
        ("rotated, TransformInputSampling off",
         lambda r: (r.SetResliceAxesDirectionCosines(*rotation), r.TransformInputSamplingOff()), 3),
        ("rotated, AutoCropOutput", lambda r: (r.SetResliceAxesDirectionCosines(*rotation), r.AutoCropOutputOn()), 3),
        ("rotated, origin", lambda r: (r.SetResliceAxesDirectionCosines(*rotation), r.SetResliceAxesOrigin(4, 5, 6)),
         2),
    ]
    for name, setup, dimensionality in cases:
        a, b = both(setup, dimensionality)
        same_geometry(a, b, name)
    # The getters, as vtkImageReslice's, before and after a value is set and reset.
    a, b = vtk.vtkImageReslice(), field_reslice()
    for what in ("GetOutputSpacing", "GetOutputOrigin", "GetOutputExtent", "GetResliceAxesDirectionCosines",
                 "GetResliceAxesOrigin", "GetBackgroundColor", "GetBackgroundLevel", "GetSlabMode",
                 "GetSlabNumberOfSlices", "GetSlabSliceSpacingFraction", "GetTransformInputSampling",
                 "GetAutoCropOutput", "GetInterpolationMode", "GetWrap", "GetMirror"):
        check(getattr(a, what)() == getattr(b, what)(), f"{what}: {getattr(a, what)()} / {getattr(b, what)()}")
    for r in (a, b):
        r.SetOutputSpacing(2, 3, 4)
        r.SetOutputExtent(1, 2, 3, 4, 5, 6)
        r.SetOutputSpacingToDefault()
        r.SetOutputExtentToDefault()
    check(a.GetOutputSpacing() == b.GetOutputSpacing() and a.GetOutputExtent() == b.GetOutputExtent(),
          f"getters after ...ToDefault: {b.GetOutputSpacing()} {b.GetOutputExtent()}")


def test_direction_cosines_in_every_form():
    cosines = (0, 1, 0, 0, 0, 1, 1, 0, 0)
    forms = [lambda r: r.SetResliceAxesDirectionCosines(*cosines),
             lambda r: r.SetResliceAxesDirectionCosines(cosines[0:3], cosines[3:6], cosines[6:9]),
             lambda r: r.SetResliceAxesDirectionCosines(list(cosines))]
    for k, form in enumerate(forms):
        a, b = vtk.vtkImageReslice(), field_reslice()
        for r in (a, b):
            form(r)
            r.SetResliceAxesOrigin((1, 2, 3))
        check(a.GetResliceAxesDirectionCosines() == b.GetResliceAxesDirectionCosines(),
              f"form {k}: {b.GetResliceAxesDirectionCosines()}")
        check(a.GetResliceAxesOrigin() == b.GetResliceAxesOrigin(), f"form {k}: {b.GetResliceAxesOrigin()}")
        x, y, z = [0.0] * 3, [0.0] * 3, [0.0] * 3
        b.GetResliceAxesDirectionCosines(x, y, z)
        check(x + y + z == [float(v) for v in cosines], f"form {k}: the three-vector getter gives {x} {y} {z}")


def test_permutations_sample_the_same_points():
    worst, count = 0.0, 0
    for cosines in permutations():
        for dimensionality in (2, 3):
            def setup(r, cosines=cosines):
                r.SetResliceAxesDirectionCosines(*cosines)
                r.SetResliceAxesOrigin(4.5, 5.0, 5.5)  # on a voxel of V
            a, b = both(setup, dimensionality)
            same_geometry(a, b, f"permutation {cosines}, dimensionality {dimensionality}")
            worst = max(worst, largest_difference(a, b))
            count += 1
    print(f"{count} permuted reslices: largest difference {worst:.3g} (intensity in [0, 1])")
    check(worst < 1e-5, f"permuted reslices differ by {worst}")


def test_information_input():
    # A second image whose geometry gives both filters their defaults (VTK's ResliceInformationInput case).
    other = vtk.vtkImageData()
    other.SetExtent(0, 8, 0, 9, 2, 7)  # inside V: vtkImageReslice gives 0 outside its input, the field does not
    other.SetSpacing(1.0, 0.5, 1.0)
    other.SetOrigin(0.5, 1.0, 1.5)
    for name, setup in (("information input", lambda r: None),
                        ("information input, permuted", lambda r: r.SetResliceAxesDirectionCosines(0, 1, 0, 1, 0, 0,
                                                                                                   0, 0, -1)),
                        ("information input, spacing set (it wins)", lambda r: r.SetOutputSpacing(0.5, 0.5, 0.5))):
        a, b = both(setup, 3, information=other)
        same_geometry(a, b, name)
        worst = largest_difference(a, b)
        check(worst < 1e-5, f"{name}: values differ by {worst}")


def test_reslice_transform():
    # A linear transform is applied to the grid after the axes: a rotation by 90 degrees about z and a whole-voxel
    # translation keeps the samples on V's voxels.
    transform = vtk.vtkTransform()
    transform.Translate(5.0, 4.0, 5.0)
    transform.RotateZ(90)
    transform.Translate(-5.0, -4.0, -5.0)

    def setup(r):
        r.SetResliceTransform(transform)
        r.SetOutputSpacing(0.5, 0.5, 0.5)
        r.SetOutputOrigin(-0.5, 0.0, 0.5)
        r.SetOutputExtent(3, 18, 1, 16, 2, 14)  # every sample inside V
    a, b = both(setup, 3)
    same_geometry(a, b, "ResliceTransform")
    worst = largest_difference(a, b)
    print(f"linear ResliceTransform: largest difference {worst:.3g}")
    check(worst < 1e-5, f"ResliceTransform: values differ by {worst}")
    # The same as the axes composed by hand.
    composed = vtk.vtkMatrix4x4()
    vtk.vtkMatrix4x4.Multiply4x4(transform.GetMatrix(), vtk.vtkMatrix4x4(), composed)
    c = field_reslice()
    c.SetInformationInput(V)
    c.SetOutputDimensionality(3)
    c.SetResliceAxes(composed)
    c.SetOutputSpacing(0.5, 0.5, 0.5)
    c.SetOutputOrigin(-0.5, 0.0, 0.5)
    c.SetOutputExtent(3, 18, 1, 16, 2, 14)
    c.Update()
    check(largest_difference(b, c.GetOutput()) < 1e-6, "ResliceTransform against the axes composed with it")
    # A non-linear transform is an error that names it, and the output is empty.
    r = field_reslice()
    r.SetResliceTransform(vtk.vtkSphericalTransform())
    messages = []
    r.AddObserver("ErrorEvent", lambda caller, event, data=None: messages.append(event))
    r.Update()
    check(r.GetOutput().GetNumberOfPoints() == 0, "a non-linear transform rendered an output")
    check(len(messages) > 0, "a non-linear transform gave no error")


def test_slabs():
    # A slab of 3 slices, the voxel spacing apart along the normal: vtkImageReslice's slab of V and the field's slab
    # sample the same points and combine them alike, for each mode.
    for mode in ("Min", "Max", "Mean", "Sum"):
        def setup(r, mode=mode):
            r.SetResliceAxesOrigin(4.5, 5.0, 5.5)
            r.SetSlabNumberOfSlices(3)
            getattr(r, "SetSlabModeTo" + mode)()
            r.SetOutputSpacing(0.5, 0.5, 0.5)
        a, b = both(setup, 2)
        same_geometry(a, b, f"slab {mode}")
        worst = largest_difference(a, b)
        check(worst < 1e-5, f"slab {mode}: values differ by {worst}")
        check(b.GetPointData().GetScalars().GetRange()[1] > 0.05, f"slab {mode}: an empty image")
    print("slabs of 3 slices: min, max, mean and sum as vtkImageReslice's")


def test_background_and_accepted_calls():
    # Samples outside the field's padded bounds take BackgroundLevel; the calls that have no meaning for a field are
    # accepted and change nothing.
    r = field_reslice()
    r.SetOutputSpacing(1, 1, 1)
    r.SetOutputOrigin(-30, -30, 0)
    r.SetOutputExtent(0, 70, 0, 70, 0, 0)
    r.SetResliceAxesOrigin(0, 0, 5)
    r.Update()
    plain = vtk.vtkImageData()
    plain.DeepCopy(r.GetOutput())
    r.SetBackgroundLevel(0.25)
    r.SetInterpolationModeToCubic()
    r.WrapOn()
    r.MirrorOn()
    r.SetBorder(0)
    r.OptimizationOff()
    r.Update()
    first, far = plain.ComputePointId([0, 0, 0]), plain.ComputePointId([35, 35, 0])
    got = r.GetOutput().GetPointData().GetScalars()
    check(abs(got.GetTuple1(first) - 0.25) < 1e-7, f"background level outside the field: {got.GetTuple1(first)}")
    check(got.GetTuple1(far) == plain.GetPointData().GetScalars().GetTuple1(far), "inside the field: changed")
    check(plain.GetPointData().GetScalars().GetRange()[1] > 0.05, "the plane misses the field")


def test_output_types_shift_and_scale():
    # vtkImageReslice's OutputScalarType, ScalarShift and ScalarScale on the field's own volume (in 8-bit gray
    # levels, 255 V, for the integer types, as the field's integer outputs are round(255 I)): the same values, rounded
    # and clamped alike (within one gray level where 255 V and 255 I round differently), and the same type; the
    # Interpolator is accepted.
    levels = vtk.vtkImageShiftScale()
    levels.SetInputData(V)
    levels.SetScale(255.0)
    levels.SetOutputScalarTypeToFloat()
    levels.Update()
    cases = [(vtk.VTK_FLOAT, 0.0, 1.0, 1e-6), (vtk.VTK_DOUBLE, 0.1, 2.0, 1e-6), (vtk.VTK_UNSIGNED_CHAR, 0.0, 3.0, 1.0),
             (vtk.VTK_SHORT, -100.0, 2.0, 1.0), (vtk.VTK_UNSIGNED_SHORT, -20.0, 1.0, 1.0), (vtk.VTK_INT, 0.0, 1.0, 1.0)]
    for scalar_type, shift, scale, tolerance in cases:
        integer = scalar_type not in (vtk.VTK_FLOAT, vtk.VTK_DOUBLE)

        def setup(r):
            r.SetOutputScalarType(scalar_type)
            r.SetScalarShift(shift)
            r.SetScalarScale(scale)
            r.SetResliceAxesOrigin(0.0, 0.0, 4.5)

        a = vtk.vtkImageReslice()
        a.SetInputData(levels.GetOutput() if integer else V)
        a.SetInterpolationModeToNearestNeighbor()
        b = field_reslice()
        b.SetInformationInput(V)
        b.SetInterpolator(vtk.vtkImageInterpolator())
        for r in (a, b):
            r.SetOutputDimensionality(2)
            setup(r)
            r.Update()
        name = vtk.vtkImageScalarTypeNameMacro(scalar_type) if hasattr(vtk, "vtkImageScalarTypeNameMacro") else scalar_type
        same_geometry(a.GetOutput(), b.GetOutput(), f"type {name}")
        types = a.GetOutput().GetScalarType(), b.GetOutput().GetScalarType()
        check(types[0] == types[1] == scalar_type, f"type {name}: vtkImageReslice {types[0]}, field {types[1]}")
        difference = largest_difference(a.GetOutput(), b.GetOutput())
        check(difference <= tolerance, f"type {name}, shift {shift}, scale {scale}: values differ by {difference}")
        low, high = b.GetOutput().GetPointData().GetScalars().GetRange()
        if scalar_type == vtk.VTK_UNSIGNED_CHAR:
            check(high == 255.0, f"unsigned char x 3: the largest value {high} is not clamped to 255")
        if scalar_type == vtk.VTK_SHORT:
            check(low < 0, f"short shifted by -100: no negative value ({low})")
        if scalar_type == vtk.VTK_UNSIGNED_SHORT:
            check(low == 0.0, f"unsigned short shifted by -20: the smallest value {low} is not clamped to 0")
    check(isinstance(b.GetInterpolator(), vtk.vtkImageInterpolator), "the Interpolator is not held")


def test_slicer_style_view():
    # A 3D Slicer-style slice view, unchanged from a volume's: the plane given by SetResliceAxes and moved by a
    # SetResliceTransform, the slice into vtkImageMapToColors and an image actor, rendered off screen. The same
    # script on V through vtkImageReslice and on the field: the same image on the screen.
    axes = vtk.vtkMatrix4x4()
    for row, value in enumerate((4.5, 5.0, 5.5)):
        axes.SetElement(row, 3, value)
    move = vtk.vtkTransform()  # the plane turned about its centre: every sample stays on a voxel of V
    move.Translate(4.5, 5.0, 5.5)
    move.RotateX(90)
    move.Translate(-4.5, -5.0, -5.5)
    table = vtk.vtkLookupTable()
    table.SetRange(0.0, 1.0)
    table.SetValueRange(0.0, 1.0)
    table.SetSaturationRange(0.0, 0.0)
    table.SetRampToLinear()
    table.Build()
    screens = []
    for reslice in (vtk.vtkImageReslice(), field_reslice()):
        if isinstance(reslice, vtk.vtkImageReslice):
            reslice.SetInputData(V)
            reslice.SetInterpolationModeToNearestNeighbor()
        else:
            reslice.SetInformationInput(V)
        reslice.SetOutputDimensionality(2)
        reslice.SetResliceAxes(axes)
        reslice.SetResliceTransform(move)
        reslice.SetOutputSpacing(0.5, 0.5, 0.5)
        reslice.SetOutputOrigin(-4.0, -4.0, 0.0)
        reslice.SetOutputExtent(0, 16, 0, 16, 0, 0)
        colors = vtk.vtkImageMapToColors()
        colors.SetLookupTable(table)
        colors.SetInputConnection(reslice.GetOutputPort())
        actor = vtk.vtkImageActor()
        actor.GetMapper().SetInputConnection(colors.GetOutputPort())
        renderer = vtk.vtkRenderer()
        renderer.AddActor(actor)
        window = vtk.vtkRenderWindow()
        window.SetOffScreenRendering(1)
        window.SetSize(120, 120)
        window.AddRenderer(renderer)
        renderer.ResetCamera()
        window.Render()
        grab = vtk.vtkWindowToImageFilter()
        grab.SetInput(window)
        grab.Update()
        screen = vtk.vtkImageData()
        screen.DeepCopy(grab.GetOutput())
        screens.append(screen)
        window.Finalize()
    scalars = [s.GetPointData().GetScalars() for s in screens]
    values = [[scalars[k].GetComponent(i, 0) for i in range(scalars[k].GetNumberOfTuples())] for k in range(2)]
    differ = sum(1 for x, y in zip(*values) if abs(x - y) > 1)
    check(max(values[1]) - min(values[1]) > 20, "the field's slice view is blank")
    check(differ == 0, f"the slice views differ on {differ} of {len(values[0])} screen pixels")
    print(f"Slicer-style view (SetResliceAxes, SetResliceTransform, vtkImageMapToColors, vtkImageActor): "
          f"{differ} screen pixels differ")


def test_volume_read_back_in_pieces():
    # A rendered volume written as .vti and read back by VTK's XML reader into vtkImageReslice that asks for part of
    # it (the .mha reader of VTK 9.1 can crash there).
    import os
    import tempfile
    path = os.path.join(tempfile.mkdtemp(), "volume.vti")
    writer = vtk.vtkXMLImageDataWriter()
    writer.SetFileName(path)
    writer.SetInputData(V)
    check(writer.Write() == 1, "writing the volume")
    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(path)
    cut = vtk.vtkImageReslice()
    cut.SetInputConnection(reader.GetOutputPort())
    cut.SetOutputExtent(3, 9, 2, 8, 4, 6)
    cut.SetOutputSpacing(V.GetSpacing())
    cut.SetOutputOrigin(V.GetOrigin())
    cut.SetInterpolationModeToNearestNeighbor()
    cut.Update()
    got = cut.GetOutput()
    worst = 0.0
    for k in range(4, 7):
        for j in range(2, 9):
            for i in range(3, 10):
                worst = max(worst, abs(got.GetScalarComponentAsDouble(i, j, k, 0) - V.GetScalarComponentAsDouble(i, j, k, 0)))
    check(worst == 0.0, f"the volume read back differs by {worst}")


def main():
    test_options_and_defaults()
    test_direction_cosines_in_every_form()
    test_permutations_sample_the_same_points()
    test_information_input()
    test_reslice_transform()
    test_slabs()
    test_background_and_accepted_calls()
    test_output_types_shift_and_scale()
    test_slicer_style_view()
    test_volume_read_back_in_pieces()
    if FAILURES:
        print(f"{len(FAILURES)} failures")
        sys.exit(1)
    print("vtkImageReslice's contract: all cases pass")


if __name__ == "__main__":
    main()

"""vtkImageReslice's contract on a Gaussian field (issue 57): each case runs twice, once on a voxel volume through
vtkImageReslice and once on the field the volume was rendered from through vtkGaussianFieldReslice, and asserts the
same output geometry; where the samples lie on the volume's voxels, the same values.

The volume V is the field rendered by vtkGaussianFieldReslice on a 0.5 mm grid with a thin beam (ElevationSigma
1e-4 mm), so that a sample of the field does not depend on the orientation of the slice it is rendered in: resliced by
vtkImageReslice at V's voxels (nearest neighbour), V's values are the field's at the same points. The field side takes
V as its InformationInput, which stands for vtkImageReslice's input: the defaults come from its geometry.

Sampling grids that are not a stack of orthogonal planes: sheared axes and a vtkGeneralTransform whose samples land on
V's voxels against vtkImageReslice on V; bent grids (thin-plate spline, spherical and perspective transforms, a
perspective ResliceAxes), whose samples do not, against the field rendered alone at each sample's point (computed here
with TransformPoint), with the thin beam and with a thick one along the local normal. Stencils: SetStencilData against
vtkImageReslice's on V; the stencil output (GenerateStencilOutput) against the samples BackgroundLevel fills and the
padded bounds for a field without training geometry, and against the Coverage array (StencilCoverageThreshold) for a
field with one.

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


def agree(a, b, name, printed=None, nonempty=False):
    """vtkImageReslice's output `a` and the field's `b`: the same geometry and values within 1e-5 (intensity in
    [0, 1]); with `nonempty`, the field's image not empty. Prints the largest difference after `printed`."""
    same_geometry(a, b, name)
    worst = largest_difference(a, b)
    if printed is not None:
        print(f"{printed}: largest difference {worst:.3g}")
    check(worst < 1e-5, f"{name}: values differ by {worst}")
    if nonempty:
        check(b.GetPointData().GetScalars().GetRange()[1] > 0.05, f"{name}: an empty image")
    return worst


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
        agree(*both(setup, 3, information=other), name)


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
    agree(a, b, "ResliceTransform", "linear ResliceTransform")
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
    # A non-linear transform is no longer an error: it renders the whole grid (values: test_bent_grids_point_by_point).
    r = field_reslice()
    r.SetResliceTransform(vtk.vtkSphericalTransform())
    r.SetResliceAxesOrigin(9.0, 0.8, 0.7)  # (r, phi, theta) inside the field
    r.SetOutputSpacing(0.25, 0.05, 0.05)
    r.SetOutputOrigin(0.0, 0.0, 0.0)
    r.SetOutputExtent(0, 4, 0, 4, 0, 0)
    messages = []
    r.AddObserver("ErrorEvent", lambda caller, event, data=None: messages.append(event))
    r.Update()
    check(r.GetOutput().GetNumberOfPoints() == 25 and not messages,
          f"a non-linear transform: {r.GetOutput().GetNumberOfPoints()} samples, {len(messages)} errors")


def test_sheared_axes():
    # Sheared axes (x and y direction cosines not perpendicular) are rendered at each sample's own point. With
    # x = (1, 0, 0), y = (1, 1, 0) / sqrt(2) and a y spacing of 0.5 sqrt(2), sample (i, j, k) lies at
    # (0.5 (i + j), 0.5 j, 0.5 k) from the axes' origin: on a voxel of V when that origin is one, so vtkImageReslice on
    # V gives the field's values there. The extents keep every sample inside V (i + j <= 22, j <= 20, k <= 18).
    h = math.sqrt(0.5)
    cases = [
        # name, direction cosines, spacing, extent, dimensionality, axes origin (a voxel of V)
        ("x, y sheared in z = const", (1, 0, 0, h, h, 0, 0, 0, 1), (0.5, 0.5 / h, 0.5), (0, 10, 0, 12, 0, 18), 3,
         (-0.5, 0.0, 0.5)),
        # sample (i, j, k) at (0.5 k, 0.5 (i + j), 0.5 j): k <= 22, i + j <= 20, j <= 18
        ("x along y, y between y and z", (0, 1, 0, 0, h, h, 1, 0, 0), (0.5, 0.5 / h, 0.5), (0, 8, 0, 12, 0, 22), 3,
         (-0.5, 0.0, 0.5)),
        # the stack's axis tilted too: sample (i, j, k) at (0.5 (i + j + k), 0.5 j, 0.5 k)
        ("x, y sheared, stack axis tilted", (1, 0, 0, h, h, 0, h, 0, h), (0.5, 0.5 / h, 0.5 / h),
         (0, 8, 0, 6, 0, 8), 3, (-0.5, 0.0, 0.5)),
        ("one sheared slice", (1, 0, 0, h, h, 0, 0, 0, 1), (0.5, 0.5 / h, 0.5), (0, 10, 0, 12, 0, 0), 2,
         (-0.5, 0.0, 4.5)),
    ]
    for name, cosines, spacing, extent, dimensionality, origin in cases:
        def setup(r, cosines=cosines, spacing=spacing, extent=extent, origin=origin):
            r.SetResliceAxesDirectionCosines(*cosines)
            r.SetResliceAxesOrigin(*origin)
            r.SetOutputSpacing(*spacing)
            r.SetOutputOrigin(0.0, 0.0, 0.0)
            r.SetOutputExtent(*extent)
        agree(*both(setup, dimensionality), f"sheared axes, {name}", f"sheared axes, {name}", nonempty=True)
    # Parallel x and y have no plane: still an error, with an empty output.
    r = field_reslice()
    r.SetResliceAxesDirectionCosines(1, 0, 0, 1, 0, 0, 0, 0, 1)
    messages = []
    r.AddObserver("ErrorEvent", lambda caller, event, data=None: messages.append(event))
    r.Update()
    check(r.GetOutput().GetNumberOfPoints() == 0, "parallel x and y axes rendered an output")
    check(len(messages) > 0, "parallel x and y axes gave no error")


_POINT_RENDERERS = {}


def field_at(point, cosines=(1, 0, 0, 0, 1, 0, 0, 0, 1), sigma=1e-4):
    """The field rendered alone at `point` (mm): a 1 x 1 slice through it whose axes are `cosines` (x, y, normal), with
    elevation beam `sigma` (mm). With the thin beam the value does not depend on the axes; with a thick one the beam
    lies along the normal."""
    r = _POINT_RENDERERS.get(sigma)
    if r is None:
        r = field_reslice()
        r.SetElevationSigma(sigma)
        r.SetOutputDimensionality(2)
        r.SetOutputSpacing(0.5, 0.5, 0.5)
        r.SetOutputOrigin(0.0, 0.0, 0.0)
        r.SetOutputExtent(0, 0, 0, 0, 0, 0)
        _POINT_RENDERERS[sigma] = r
    r.SetResliceAxesDirectionCosines(*cosines)
    r.SetResliceAxesOrigin(*point)
    r.Update()
    return r.GetOutput().GetPointData().GetScalars().GetTuple1(0)


class Warp:
    """A bent sampling grid: ResliceAxes (4 x 4 rows, perspective allowed), a ResliceTransform (or None), and the
    output grid, with the sample points computed here from the definition: sample (i, j, k) lies at
    T(ResliceAxes * (OutputOrigin + (i, j, k) * OutputSpacing)), the axes' product divided by its fourth coordinate."""

    def __init__(self, name, axes, transform, origin, spacing, extent, dimensionality):
        self.name, self.transform = name, transform
        self.axes = [list(row) for row in axes]
        self.origin, self.spacing, self.extent, self.dimensionality = origin, spacing, extent, dimensionality

    def matrix(self):
        m = vtk.vtkMatrix4x4()
        for row in range(4):
            for column in range(4):
                m.SetElement(row, column, self.axes[row][column])
        return m

    def setup(self, r):
        r.SetOutputDimensionality(self.dimensionality)
        r.SetResliceAxes(self.matrix())
        if self.transform is not None:
            r.SetResliceTransform(self.transform)
        r.SetOutputOrigin(*self.origin)
        r.SetOutputSpacing(*self.spacing)
        r.SetOutputExtent(*self.extent)

    def point(self, index):
        local = [self.origin[c] + index[c] * self.spacing[c] for c in range(3)] + [1.0]
        h = [sum(self.axes[row][c] * local[c] for c in range(4)) for row in range(4)]
        p = [h[c] / h[3] for c in range(3)]
        return list(self.transform.TransformPoint(p)) if self.transform is not None else p

    def unwarped(self, index):
        """The sample's point without the bend: the axes' affine part alone, without T."""
        local = [self.origin[c] + index[c] * self.spacing[c] for c in range(3)] + [1.0]
        return [sum(self.axes[row][c] * local[c] for c in range(4)) for row in range(3)]

    def local_axes(self, index, step=1e-3):
        """The local pixel axes at a sample, orthonormalised: the point's central differences along i and j (step in
        samples), their normal last; direction cosines as SetResliceAxesDirectionCosines takes them."""
        def along(c):
            plus, minus = list(index), list(index)
            plus[c] += step
            minus[c] -= step
            return [(a - b) / (2 * step) for a, b in zip(self.point(plus), self.point(minus))]
        return orthonormal(along(0), along(1))

    def indices(self, count, seed):
        rng = random.Random(seed)
        e = self.extent
        k_range = (e[4], e[5]) if self.dimensionality == 3 else (0, 0)
        return [(rng.randint(e[0], e[1]), rng.randint(e[2], e[3]), rng.randint(*k_range)) for _ in range(count)]


def orthonormal(u, v):
    """Direction cosines x, y, z from two non-parallel vectors: x along u, y in the plane of u and v, z = x cross y."""
    def unit(w):
        n = math.sqrt(sum(c * c for c in w))
        return [c / n for c in w]
    x = unit(u)
    d = sum(a * b for a, b in zip(v, x))
    y = unit([b - d * a for a, b in zip(x, v)])
    z = [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
    return x + y + z


def rotation_axes(angle, origin):
    """A rotation by `angle` about z and then about x, with `origin`, as 4 x 4 rows."""
    c, s = math.cos(angle), math.sin(angle)
    z = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    x = [[1, 0, 0], [0, c, -s], [0, s, c]]
    m = [[sum(x[r][k] * z[k][col] for k in range(3)) for col in range(3)] for r in range(3)]
    return [m[0] + [origin[0]], m[1] + [origin[1]], m[2] + [origin[2]], [0, 0, 0, 1]]


def thin_plate_spline():
    """A thin-plate spline that moves three landmarks inside the field by about 1 mm and holds the box's corners."""
    source, target = vtk.vtkPoints(), vtk.vtkPoints()
    moved = {(5.0, 5.0, 5.0): (5.8, 4.4, 5.6), (3.5, 6.5, 4.0): (2.9, 7.1, 4.7), (6.5, 3.5, 6.5): (7.2, 3.9, 5.8)}
    import itertools
    corners = [tuple(float(v) for v in c) for c in itertools.product((1.0, 9.0), repeat=3)]
    for p in corners + list(moved):
        source.InsertNextPoint(p)
        target.InsertNextPoint(moved.get(p, p))
    t = vtk.vtkThinPlateSplineTransform()
    t.SetSourceLandmarks(source)
    t.SetTargetLandmarks(target)
    t.SetBasisToR()
    return t


def perspective_transform():
    """A vtkPerspectiveTransform: (5, 5, 5) moved to the origin, a perspective row (0.015, -0.01, 0.03, 1), and back."""
    t = vtk.vtkPerspectiveTransform()
    t.PostMultiply()
    t.Translate(-5.0, -5.0, -5.0)
    p = vtk.vtkMatrix4x4()
    for column, value in enumerate((0.015, -0.01, 0.03, 1.0)):
        p.SetElement(3, column, value)
    t.Concatenate(p)
    t.Translate(5.0, 5.0, 5.0)
    return t


def warps():
    """The bent grids of the point-by-point tests, each inside the field's region."""
    perspective_axes = rotation_axes(0.4, (5.0, 5.0, 5.0))
    perspective_axes[3] = [0.02, -0.015, 0.01, 1.0]
    return [
        Warp("thin-plate spline, a rotated slice", rotation_axes(0.3, (5.0, 5.0, 5.0)), thin_plate_spline(),
             (-4.0, -4.0, 0.0), (0.5, 0.5, 0.5), (0, 16, 0, 16, 0, 0), 2),
        Warp("thin-plate spline, a stack", rotation_axes(0.0, (5.0, 5.0, 4.0)), thin_plate_spline(),
             (-3.0, -3.0, 0.0), (0.5, 0.5, 0.5), (0, 12, 0, 12, 0, 4), 3),
        Warp("vtkPerspectiveTransform, a rotated slice", rotation_axes(0.3, (5.0, 5.0, 5.5)), perspective_transform(),
             (-4.0, -4.0, 0.0), (0.5, 0.5, 0.5), (0, 16, 0, 16, 0, 0), 2),
        Warp("perspective ResliceAxes, a stack", perspective_axes, None,
             (-3.5, -3.5, -1.0), (0.5, 0.5, 0.5), (0, 14, 0, 14, 0, 4), 3),
        # (r, phi, theta) -> (r sin phi cos theta, r sin phi sin theta, r cos phi): r 7 to 11 mm, phi 0.6 to 1.1
        Warp("vtkSphericalTransform", [[1, 0, 0, 7.0], [0, 1, 0, 0.6], [0, 0, 1, 0.5], [0, 0, 0, 1]],
             vtk.vtkSphericalTransform(), (0.0, 0.0, 0.0), (0.25, 0.05, 1.0), (0, 16, 0, 10, 0, 0), 2),
    ]


def render_warp(warp, sigma=1e-4):
    r = field_reslice()
    r.SetElevationSigma(sigma)
    messages = []
    r.AddObserver("ErrorEvent", lambda caller, event, data=None: messages.append(event))
    warp.setup(r)
    r.Update()
    e = warp.extent
    count = (e[1] - e[0] + 1) * (e[3] - e[2] + 1) * ((e[5] - e[4] + 1) if warp.dimensionality == 3 else 1)
    rendered = not messages and r.GetOutput().GetNumberOfPoints() == count
    check(rendered, f"{warp.name}: not rendered ({len(messages)} errors, {r.GetOutput().GetNumberOfPoints()} samples)")
    return r.GetOutput() if rendered else None


def test_general_transform_on_voxels():
    # A vtkGeneralTransform (not a vtkHomogeneousTransform, so rendered point by point) that concatenates a rotation
    # by 90 degrees about z and whole-voxel translations: every sample still lands on a voxel of V, and vtkImageReslice
    # on V gives the field's values.
    general = vtk.vtkGeneralTransform()
    general.Translate(5.0, 4.0, 5.0)
    general.RotateZ(90)
    general.Translate(-5.0, -4.0, -5.0)
    check(not general.IsA("vtkHomogeneousTransform"), "vtkGeneralTransform is homogeneous")
    for dimensionality, extent in ((3, (3, 18, 1, 16, 2, 14)), (2, (3, 18, 1, 16, 0, 0))):
        def setup(r, extent=extent):
            r.SetResliceTransform(general)
            r.SetResliceAxesOrigin(0.0, 0.0, 5.5)
            r.SetOutputSpacing(0.5, 0.5, 0.5)
            r.SetOutputOrigin(-0.5, 0.0, -5.0)
            r.SetOutputExtent(*extent)  # every sample inside V
        name = f"vtkGeneralTransform, dimensionality {dimensionality}"
        agree(*both(setup, dimensionality), name, name, nonempty=True)


def test_bent_grids_point_by_point():
    # Non-linear ResliceTransforms (thin-plate spline, spherical) and perspective (a vtkPerspectiveTransform, a
    # ResliceAxes with a perspective row): each output sample is the field at T(ResliceAxes * (origin + index *
    # spacing)), computed here with the transform's TransformPoint and rendered alone as a 1 x 1 slice (the thin beam
    # makes the value independent of the slice's orientation). The bend must matter: the unbent points give other
    # values.
    for warp in warps():
        out = render_warp(warp)
        if out is None:
            continue
        worst, moved, lit = 0.0, 0.0, 0
        for index in warp.indices(30, seed=11):
            got = out.GetScalarComponentAsDouble(*index, 0)
            expected = field_at(warp.point(index))
            if abs(got - expected) >= 1e-5:
                print(f"  {warp.name}, sample {index} at {[round(v, 4) for v in warp.point(index)]}: "
                      f"field {got:.6f}, rendered alone {expected:.6f}")
            worst = max(worst, abs(got - expected))
            moved = max(moved, abs(field_at(warp.unwarped(index)) - expected))
            lit += expected > 0.02
        print(f"{warp.name}: 30 samples, largest difference {worst:.3g} from a render at each point "
              f"(the unbent points differ by up to {moved:.3g})")
        check(worst < 1e-5, f"{warp.name}: samples differ from the field at their points by {worst}")
        check(lit >= 10, f"{warp.name}: only {lit} of 30 samples see the field")
        check(moved > 0.02, f"{warp.name}: the bend changes no sample ({moved})")


def test_bent_grid_beam_along_local_normal():
    # With a thick beam (ElevationSigma 1 mm) the value depends on the beam's direction: each sample of a bent grid is
    # the field rendered at its point with the beam along the local normal, the cross product of the point's
    # derivatives along i and j (central differences of TransformPoint here), and not along the unbent slice's normal.
    tolerance = 1e-4
    for warp in warps():
        out = render_warp(warp, sigma=1.0)
        if out is None:
            continue
        unbent = warp.matrix()
        flat = [unbent.GetElement(row, column) for column in range(3) for row in range(3)]
        flat = orthonormal(flat[0:3], flat[3:6])
        worst, along_flat = 0.0, 0.0
        for index in warp.indices(12, seed=5):
            point = warp.point(index)
            got = out.GetScalarComponentAsDouble(*index, 0)
            expected = field_at(point, warp.local_axes(index), sigma=1.0)
            if abs(got - expected) >= tolerance:
                print(f"  {warp.name}, sample {index} at {[round(v, 4) for v in point]}: field {got:.6f}, rendered "
                      f"alone with the beam along the local normal {warp.local_axes(index)[6:]}: {expected:.6f}")
            worst = max(worst, abs(got - expected))
            along_flat = max(along_flat, abs(field_at(point, flat, sigma=1.0) - expected))
        print(f"{warp.name}, ElevationSigma 1: largest difference {worst:.3g} from the beam along the local normal, "
              f"{along_flat:.3g} between that and the unbent normal")
        check(worst < tolerance, f"{warp.name}, ElevationSigma 1: the beam is not along the local normal ({worst})")
        check(along_flat > 10 * tolerance,
              f"{warp.name}, ElevationSigma 1: the unbent normal gives the same values ({along_flat}): no test")


def sphere_stencil(origin, spacing, extent, centre, radius):
    """A vtkImageStencilData on an output grid: the samples within `radius` of `centre` (the grid's coordinates)."""
    sphere = vtk.vtkSphere()
    sphere.SetCenter(*centre)
    sphere.SetRadius(radius)
    source = vtk.vtkImplicitFunctionToImageStencil()
    source.SetInput(sphere)
    source.SetOutputOrigin(*origin)
    source.SetOutputSpacing(*spacing)
    source.SetOutputWholeExtent(*extent)
    source.Update()
    return source.GetOutput()


def test_stencil_input():
    # SetStencilData, as vtkImageReslice's: the output's scalars outside the stencil are BackgroundLevel, those inside
    # are unchanged. On planes inside V whose samples lie on V's voxels, vtkImageReslice on V with the same stencil
    # gives the same image; the other arrays (ScatteringField) are not touched.
    cases = [
        ("a slice", 2, (-4.0, -4.0, 0.0), (0, 16, 0, 16, 0, 0), (0.0, 0.5, 0.0), 3.0),
        ("a stack", 3, (-4.0, -4.0, -3.0), (0, 16, 0, 16, 0, 12), (0.5, 0.0, 0.0), 3.5),
    ]
    for name, dimensionality, origin, extent, centre, radius in cases:
        stencil = sphere_stencil(origin, (0.5, 0.5, 0.5), extent, centre, radius)

        def setup(r, origin=origin, extent=extent, stencil=stencil):
            r.SetResliceAxesOrigin(4.5, 5.0, 5.5)  # on a voxel of V
            r.SetOutputSpacing(0.5, 0.5, 0.5)
            r.SetOutputOrigin(*origin)
            r.SetOutputExtent(*extent)
            r.SetBackgroundLevel(0.3)
            r.SetStencilData(stencil)
        a, b = both(setup, dimensionality)
        name = f"stencil input, {name}"
        agree(a, b, name, f"{name} (vtkImageReslice with the same stencil)")
        field_values = values(b)
        outside = sum(1 for v in field_values if abs(v - 0.3) < 1e-7)
        check(0 < outside < len(field_values),
              f"{name}: {outside} of {len(field_values)} samples at the background level")
        r = field_reslice()
        r.SetInformationInput(V)
        r.SetOutputDimensionality(dimensionality)
        setup(r)
        check(r.GetStencil() is stencil, f"{name}: GetStencil does not return the stencil given")
        r.OutputScatteringFieldOn()
        r.Update()
        with_stencil = vtk.vtkFloatArray()
        with_stencil.DeepCopy(r.GetOutput().GetPointData().GetArray("ScatteringField"))
        r.SetStencilData(None)
        r.Update()
        check(r.GetStencil() is None, f"{name}: the stencil is still held after SetStencilData(None)")
        plain = r.GetOutput()
        check(largest_difference(plain, b) > 0.05, f"{name}: the stencil changes nothing")
        s = plain.GetPointData().GetArray("ScatteringField")
        check(s is not None and all(abs(s.GetTuple1(p) - with_stencil.GetTuple1(p)) < 1e-6
                                    for p in range(s.GetNumberOfTuples())),
              f"{name}: the stencil changes the ScatteringField array")


def padded_field_box(field):
    """The field's padded bounds, computed here: the means' bounds padded by 3 x the largest scale."""
    bounds = field.GetPoints().GetBounds()
    scale = field.GetPointData().GetArray("Scale")
    pad = 3 * max(scale.GetRange(c)[1] for c in range(3))
    return [b + (pad if k % 2 else -pad) for k, b in enumerate(bounds)]


def stencil_of(r):
    """GetStencilOutput after an update, with checks that port 1 gives the same stencil and that it lies on the image
    output's grid."""
    stencil, image = r.GetStencilOutput(), r.GetOutput()
    check(stencil is not None and stencil.IsA("vtkImageStencilData"), "GetStencilOutput is not a vtkImageStencilData")
    port = r.GetStencilOutputPort()
    check(port is not None and port.GetIndex() == 1 and port.GetProducer() is r, "GetStencilOutputPort is not port 1")
    check(r.GetOutputDataObject(1) is stencil, "output port 1 does not hold GetStencilOutput")
    ok = stencil.GetExtent() == image.GetExtent() and \
        all(abs(x - y) < 1e-9 for x, y in zip(stencil.GetSpacing(), image.GetSpacing())) and \
        all(abs(x - y) < 1e-9 for x, y in zip(stencil.GetOrigin(), image.GetOrigin()))
    check(ok, f"stencil geometry {stencil.GetExtent()} {stencil.GetSpacing()} {stencil.GetOrigin()}, image "
              f"{image.GetExtent()} {image.GetSpacing()} {image.GetOrigin()}")
    return stencil


def samples(image):
    e = image.GetExtent()
    for k in range(e[4], e[5] + 1):
        for j in range(e[2], e[3] + 1):
            for i in range(e[0], e[1] + 1):
                yield i, j, k


def test_stencil_output_without_training_geometry():
    # GenerateStencilOutput (default off, as vtkImageReslice's): a field without training geometry marks the samples
    # inside its padded bounds, the samples BackgroundLevel does not fill. On planes that reach outside the field,
    # with a marker background level: inside == not the marker, sample by sample, and inside == within the padded
    # bounds computed here.
    check(field_reslice().GetGenerateStencilOutput() == vtk.vtkImageReslice().GetGenerateStencilOutput() == 0,
          "GenerateStencilOutput is not off by default")
    marker = 2.5
    box = padded_field_box(FIELD)
    c, s = math.cos(0.3), math.sin(0.3)
    planes = [("axis-aligned plane", (1, 0, 0, 0, 1, 0, 0, 0, 1), (0.0, 0.0, 5.0), (-30, -30, 0), (0, 70, 0, 70, 0, 0),
               2),
              ("rotated plane", (c, 0, s, 0, 1, 0, -s, 0, c), (5.0, 5.0, 5.0), (-12, -12, 0), (0, 48, 0, 48, 0, 0), 2),
              ("stack", (1, 0, 0, 0, 1, 0, 0, 0, 1), (0.0, 0.0, 0.0), (-4, -4, -4), (0, 18, 0, 18, 0, 18), 3)]
    for name, cosines, axes_origin, origin, extent, dimensionality in planes:
        r = field_reslice()
        r.SetOutputDimensionality(dimensionality)
        r.SetResliceAxesDirectionCosines(*cosines)
        r.SetResliceAxesOrigin(*axes_origin)
        r.SetOutputSpacing(1, 1, 1)
        r.SetOutputOrigin(*origin)
        r.SetOutputExtent(*extent)
        r.SetBackgroundLevel(marker)
        r.GenerateStencilOutputOn()
        r.Update()
        stencil = stencil_of(r)
        image = r.GetOutput()
        wrong, off_box, inside, count = 0, 0, 0, 0
        for i, j, k in samples(image):
            value = image.GetScalarComponentAsDouble(i, j, k, 0)
            is_inside = bool(stencil.IsInside(i, j, k))
            wrong += is_inside != (value != marker)
            local = [origin[0] + i, origin[1] + j, origin[2] + k]
            point = [axes_origin[row] + sum(cosines[3 * column + row] * local[column] for column in range(3))
                     for row in range(3)]
            margins = [min(point[a] - box[2 * a], box[2 * a + 1] - point[a]) for a in range(3)]
            if abs(min(margins)) > 1e-6:
                off_box += is_inside != (min(margins) > 0)
            inside += is_inside
            count += 1
        print(f"stencil output, {name}: {inside} of {count} samples inside, {wrong} disagree with the background, "
              f"{off_box} with the padded bounds")
        check(0 < inside < count, f"stencil output, {name}: {inside} of {count} samples inside")
        check(wrong == 0, f"stencil output, {name}: {wrong} samples inside the stencil and at the background level, or "
                          f"outside it and not")
        check(off_box == 0, f"stencil output, {name}: {off_box} samples disagree with the padded bounds {box}")
    # Off again: the image does not change.
    before = vtk.vtkImageData()
    before.DeepCopy(image)
    r.GenerateStencilOutputOff()
    r.Update()
    check(largest_difference(r.GetOutput(), before) == 0, "GenerateStencilOutputOff changes the image")


def field_with_training_geometry():
    """FIELD with the training geometry of five 40 x 40 frames of 0.25 mm pixels over x, y in [0, 10] mm: four at
    z = 3, 4, 5, 6 and one tilted by 30 degrees about x through z = 2, with a disc fan mask of radius 18 pixels."""
    field = vtk.vtkPolyData()
    field.DeepCopy(FIELD)
    width = height = 40
    step = 0.25
    poses = vtk.vtkDoubleArray()
    poses.SetName("TrainingPoses")
    poses.SetNumberOfComponents(16)
    a = math.radians(30)
    frames = [[step, 0, 0, 0, 0, step, 0, 0, 0, 0, 1, z, 0, 0, 0, 1] for z in (3.0, 4.0, 5.0, 6.0)]
    frames.append([step, 0, 0, 0, 0, step * math.cos(a), -math.sin(a), 0, 0, step * math.sin(a), math.cos(a), 2.0,
                   0, 0, 0, 1])
    for pose in frames:
        poses.InsertNextTuple(pose)
    size = vtk.vtkIntArray()
    size.SetName("TrainingFrameSize")
    size.SetNumberOfComponents(2)
    size.InsertNextTuple2(width, height)
    mask = vtk.vtkUnsignedCharArray()
    mask.SetName("TrainingFanMask")
    for j in range(height):
        for i in range(width):
            mask.InsertNextValue(1 if (i - 19.5) ** 2 + (j - 19.5) ** 2 <= 18 ** 2 else 0)
    for array in (poses, size, mask):
        field.GetFieldData().AddArray(array)
    return field


def test_stencil_output_from_coverage():
    # A field with training geometry: the stencil output marks the samples whose training coverage (the Coverage array
    # of OutputCoverage, ElevationSigma 1 mm) is at least StencilCoverageThreshold (default 0.5); a higher threshold
    # marks fewer. Whether the Coverage array is output does not change the stencil.
    field = field_with_training_geometry()
    check(field_reslice().GetStencilCoverageThreshold() == 0.5, "StencilCoverageThreshold is not 0.5 by default")
    r = bigus.vtkGaussianFieldReslice()
    r.SetInputData(field)
    r.SetElevationSigma(1.0)
    r.SetOutputDimensionality(2)
    r.SetResliceAxesDirectionCosines(1, 0, 0, 0, 0, 1, 0, -1, 0)  # the plane y = 5 across the frames
    r.SetResliceAxesOrigin(0.0, 5.0, 0.0)
    r.SetOutputSpacing(0.25, 0.25, 0.25)
    r.SetOutputOrigin(-1.0, -1.0, 0.0)
    r.SetOutputExtent(0, 48, 0, 48, 0, 0)
    r.OutputCoverageOn()
    r.GenerateStencilOutputOn()
    counts = {}
    for threshold in (None, 2.0):
        if threshold is not None:
            r.SetStencilCoverageThreshold(threshold)
        r.Update()
        level = r.GetStencilCoverageThreshold()
        image = r.GetOutput()
        coverage = image.GetPointData().GetArray("Coverage")
        check(coverage is not None, "no Coverage array from a field with training geometry")
        if coverage is None:
            return
        stencil = stencil_of(r)
        wrong, inside, close = 0, 0, 0
        for i, j, k in samples(image):
            c = coverage.GetTuple1(image.ComputePointId([i, j, k]))
            is_inside = bool(stencil.IsInside(i, j, k))
            if abs(c - level) < 1e-5:
                close += 1
            else:
                wrong += is_inside != (c >= level)
            inside += is_inside
        counts[level] = inside
        print(f"stencil output from coverage, threshold {level}: {inside} of {image.GetNumberOfPoints()} samples "
              f"inside, {wrong} disagree with Coverage >= {level} ({close} within 1e-5 of it not compared)")
        check(wrong == 0, f"stencil output, threshold {level}: {wrong} samples disagree with Coverage >= {level}")
        check(0 < inside < image.GetNumberOfPoints(), f"stencil output, threshold {level}: {inside} samples inside")
    check(counts.get(2.0, 0) < counts.get(0.5, 0), f"threshold 2 marks no fewer samples than 0.5: {counts}")
    # The stencil does not need the Coverage array.
    kept = vtk.vtkImageStencilData()
    kept.DeepCopy(r.GetStencilOutput())
    r.OutputCoverageOff()
    r.Update()
    check(r.GetOutput().GetPointData().GetArray("Coverage") is None, "OutputCoverageOff still outputs Coverage")
    stencil = r.GetStencilOutput()
    differ = sum(1 for i, j, k in samples(r.GetOutput()) if stencil.IsInside(i, j, k) != kept.IsInside(i, j, k))
    check(differ == 0, f"OutputCoverageOff changes {differ} samples of the stencil")
    # A plane inside V: the stencil's geometry as vtkImageReslice's on V (which marks every sample inside there).
    for dimensionality in (2, 3):
        a, b = vtk.vtkImageReslice(), field_reslice()
        a.SetInputData(V)
        a.SetInterpolationModeToNearestNeighbor()
        b.SetInformationInput(V)
        for f in (a, b):
            f.SetOutputDimensionality(dimensionality)
            f.SetResliceAxesOrigin(4.5, 5.0, 5.5)
            f.SetOutputSpacing(0.5, 0.5, 0.5)
            f.SetOutputOrigin(-4.0, -4.0, -3.0)
            f.SetOutputExtent(0, 16, 0, 16, 0, 12)
            f.GenerateStencilOutputOn()
            f.Update()
        sa, sb = a.GetStencilOutput(), b.GetStencilOutput()
        ga = sa.GetExtent(), sa.GetSpacing(), sa.GetOrigin()
        gb = sb.GetExtent(), sb.GetSpacing(), sb.GetOrigin()
        check(ga[0] == gb[0] and all(abs(x - y) < 1e-9 for x, y in zip(ga[1] + ga[2], gb[1] + gb[2])),
              f"stencil output, dimensionality {dimensionality}: geometry vtkImageReslice {ga}, field {gb}")

def test_slabs():
    # A slab of 3 slices, the voxel spacing apart along the normal: vtkImageReslice's slab of V and the field's slab
    # sample the same points and combine them alike, for each mode.
    for mode in ("Min", "Max", "Mean", "Sum"):
        def setup(r, mode=mode):
            r.SetResliceAxesOrigin(4.5, 5.0, 5.5)
            r.SetSlabNumberOfSlices(3)
            getattr(r, "SetSlabModeTo" + mode)()
            r.SetOutputSpacing(0.5, 0.5, 0.5)
        agree(*both(setup, 2), f"slab {mode}", nonempty=True)
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
    check(r.GetInterpolationModeAsString() == "Cubic", f"interpolation mode {r.GetInterpolationModeAsString()}")
    # vtkThreadedImageAlgorithm's calls, as vtkImageReslice has them.
    r.SetNumberOfThreads(1)
    r.SetEnableSMP(False)
    r.SetSplitModeToBeam()
    r.SetDesiredBytesPerPiece(1000)
    r.SetMinimumPieceSize(4, 4, 4)
    r.Update()
    first, far = plain.ComputePointId([0, 0, 0]), plain.ComputePointId([35, 35, 0])
    got = r.GetOutput().GetPointData().GetScalars()
    check(abs(got.GetTuple1(first) - 0.25) < 1e-7, f"background level outside the field: {got.GetTuple1(first)}")
    check(got.GetTuple1(far) == plain.GetPointData().GetScalars().GetTuple1(far), "inside the field: changed")
    check(plain.GetPointData().GetScalars().GetRange()[1] > 0.05, "the plane misses the field")


def test_every_method_of_vtkImageReslice():
    # Every public method vtkImageReslice has (its own and those of vtkThreadedImageAlgorithm and above) exists on the
    # field's reslice, bar the garbage collector's ReportReferences (internal to VTK).
    missing = sorted(set(dir(vtk.vtkImageReslice)) - set(dir(bigus.vtkGaussianFieldReslice)) - {"ReportReferences"})
    check(not missing, f"vtkImageReslice's methods missing on vtkGaussianFieldReslice: {missing}")
    print(f"vtkImageReslice's {len(dir(vtk.vtkImageReslice))} attributes: all on vtkGaussianFieldReslice but ReportReferences")


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
    test_sheared_axes()
    test_general_transform_on_voxels()
    test_bent_grids_point_by_point()
    test_bent_grid_beam_along_local_normal()
    test_stencil_input()
    test_stencil_output_without_training_geometry()
    test_stencil_output_from_coverage()
    test_slabs()
    test_background_and_accepted_calls()
    test_every_method_of_vtkImageReslice()
    test_output_types_shift_and_scale()
    test_slicer_style_view()
    test_volume_read_back_in_pieces()
    if FAILURES:
        print(f"{len(FAILURES)} failures")
        sys.exit(1)
    print("vtkImageReslice's contract: all cases pass")


if __name__ == "__main__":
    main()

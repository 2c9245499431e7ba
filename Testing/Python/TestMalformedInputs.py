"""The project's malformed-input corpus (issue 56): every bad input or option the `bigus` command line can be
given, made by this script, run one by one. Each case must end with a clear error (exit 1 or 2, one line on stderr
naming the option, file, frame or field and what is wrong), never with a crash (a signal, std::bad_alloc, a
sanitizer's report), a hang (a timeout per case) or a change to the user's files: every file the case names that
existed before is byte for byte the same after, and an output that did not exist is not left behind.

Standard library only, so that it also runs against the sanitizer build's `bigus`.

Usage: TestMalformedInputs.py TESTING_DATA_DIR BIGUS_EXECUTABLE OUTPUT_DIR
Environment: BIGUS_CORPUS_TIMEOUT (seconds a case may take, default 120).
"""
import base64
import hashlib
import math
import os
import shutil
import struct
import subprocess
import sys
import time

TESTING, BIGUS, OUT = sys.argv[1:4]
TIMEOUT = float(os.environ.get("BIGUS_CORPUS_TIMEOUT", "120"))

NWIRE = os.path.join(TESTING, "nwire-phantom")
SWEEP = os.path.join(NWIRE, "NwirePhantomFreehandCropped.igs.mha")
XML = os.path.join(NWIRE, "PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml")
MALFORMED = os.path.join(TESTING, "Malformed")
FIXTURES = os.path.join(OUT, "fixtures")
RESULTS = os.path.join(OUT, "results")


# ---------------------------------------------------------------------------------------------------------------
# Fixtures: a valid field and masks as the project's formats hold them, and their malformed variants.

def data_array(name, components, values, kind="Float32"):
    """A VTK XML DataArray, inline binary: base64 of the byte count (UInt64) followed by the values."""
    code = {"Float32": "f", "Float64": "d"}[kind]
    raw = struct.pack("<%d%s" % (len(values), code), *values)
    text = base64.b64encode(struct.pack("<Q", len(raw)) + raw).decode()
    return ('<DataArray type="%s" Name="%s" NumberOfComponents="%d" format="binary">%s</DataArray>'
            % (kind, name, components, text))


def field_vtp(points, scales, rotations, reflectivities, claimed=None):
    """A Gaussian field as bigus writes it: points (mm), point data Scale, Rotation (w x y z), Reflectivity."""
    n = len(points) if claimed is None else claimed
    flat = lambda rows: [v for row in rows for v in row]  # noqa: E731
    return ('<?xml version="1.0"?>\n'
            '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n'
            '<PolyData><Piece NumberOfPoints="%d" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" '
            'NumberOfPolys="0">\n<PointData>%s%s%s</PointData>\n<Points>%s</Points>\n</Piece></PolyData>\n'
            '</VTKFile>\n' % (n, data_array("Scale", 3, flat(scales)), data_array("Rotation", 4, flat(rotations)),
                              data_array("Reflectivity", 1, reflectivities), data_array("Points", 3, flat(points))))


def good_field():
    points = [(x, y, 0.0) for x in (-2.0, 0.0, 2.0) for y in (-2.0, 0.0, 2.0)]
    return ([list(p) for p in points], [[0.8, 0.8, 0.5] for _ in points], [[1.0, 0.0, 0.0, 0.0] for _ in points],
            [0.5 for _ in points])


def write(path, data, mode="w"):
    with open(path, mode) as f:
        f.write(data)
    return path


def metaimage(path, dims, kind, payload):
    """A MetaImage (.mha) with its pixels in the file."""
    header = ("ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
              "CompressedData = False\nDimSize = %d %d %d\nElementSpacing = 1 1 1\nElementType = %s\n"
              "ElementDataFile = LOCAL\n" % (dims[0], dims[1], dims[2], kind))
    return write(path, header.encode() + payload, "wb")


def sweep_variant(name, edit):
    """The uncompressed 4-frame copy of the N-wire sweep (Malformed/copy_uncompressed.mhd) with its header edited."""
    with open(os.path.join(MALFORMED, "copy_uncompressed.mhd")) as f:
        lines = f.read().split("\n")
    lines = edit(lines)
    raw = os.path.join(FIXTURES, name + ".raw")
    shutil.copyfile(os.path.join(MALFORMED, "copy_uncompressed.raw"), raw)
    text = "\n".join(l if not l.startswith("ElementDataFile") else "ElementDataFile = " + name + ".raw"
                     for l in lines)
    return write(os.path.join(FIXTURES, name + ".mhd"), text)


def set_field(key, value):
    return lambda lines: [key + " = " + value if l.split(" = ")[0] == key else l for l in lines]


def make_fixtures():
    shutil.rmtree(OUT, ignore_errors=True)
    os.makedirs(FIXTURES)
    os.makedirs(RESULTS)
    f = {}
    points, scales, rotations, reflectivities = good_field()
    f["field"] = write(os.path.join(FIXTURES, "good.vtp"), field_vtp(points, scales, rotations, reflectivities))

    def bad_field(name, index, what, value):
        p, s, r, q = (list(map(list, points)), list(map(list, scales)), list(map(list, rotations)),
                      list(reflectivities))
        if what == "reflectivity":
            q[index] = value
        elif what == "rotation":
            r[index] = value
        elif what == "scale":
            s[index] = value
        elif what == "point":
            p[index] = value
        f[name] = write(os.path.join(FIXTURES, name + ".vtp"), field_vtp(p, s, r, q))

    nan, inf = float("nan"), float("inf")
    bad_field("field_nan_reflectivity", 4, "reflectivity", nan)
    bad_field("field_inf_reflectivity", 2, "reflectivity", inf)
    bad_field("field_zero_quaternion", 3, "rotation", [0.0, 0.0, 0.0, 0.0])
    bad_field("field_nan_quaternion", 1, "rotation", [nan, 0.0, 0.0, 1.0])
    bad_field("field_zero_scale", 5, "scale", [0.8, 0.0, 0.5])
    bad_field("field_negative_scale", 0, "scale", [-1.0, 0.8, 0.5])
    bad_field("field_huge_scale", 6, "scale", [1e30, 0.8, 0.5])
    bad_field("field_nan_position", 7, "point", [nan, 0.0, 0.0])
    bad_field("field_far_position", 8, "point", [0.0, 3e38, 0.0])
    f["field_claims_1e11_points"] = write(os.path.join(FIXTURES, "field_claims_1e11_points.vtp"),
                                          field_vtp(points, scales, rotations, reflectivities, claimed=10 ** 11))
    with open(f["field"]) as g:
        text = g.read()
    f["field_truncated"] = write(os.path.join(FIXTURES, "field_truncated.vtp"), text[: len(text) // 2])
    f["field_empty"] = write(os.path.join(FIXTURES, "field_empty.vtp"), "")
    f["field_not_xml"] = write(os.path.join(FIXTURES, "field_not_xml.vtp"), "this is not a field\n" * 10)
    f["field_without_scale"] = write(os.path.join(FIXTURES, "field_without_scale.vtp"),
                                     text.replace('Name="Scale"', 'Name="Size"'))
    f["field_binary_garbage"] = write(os.path.join(FIXTURES, "field_binary_garbage.vtp"),
                                      bytes(range(256)) * 40, "wb")
    f["fifo"] = os.path.join(FIXTURES, "pipe.vtp")
    os.mkfifo(f["fifo"])

    # Masks for the 200 x 150 N-wire frames.
    w, h = 200, 150
    f["mask_nan"] = metaimage(os.path.join(FIXTURES, "mask_nan.mha"), (w, h, 1), "MET_FLOAT",
                              struct.pack("<f", nan) * (w * h))
    f["mask_inf_pixel"] = metaimage(os.path.join(FIXTURES, "mask_inf_pixel.mha"), (w, h, 1), "MET_FLOAT",
                                    struct.pack("<f", 1.0) * (w * h - 1) + struct.pack("<f", inf))
    f["mask_wrong_size"] = metaimage(os.path.join(FIXTURES, "mask_wrong_size.mha"), (w - 1, h, 1), "MET_UCHAR",
                                     b"\x01" * ((w - 1) * h))
    f["mask_truncated"] = metaimage(os.path.join(FIXTURES, "mask_truncated.mha"), (w, h, 1), "MET_UCHAR",
                                    b"\x01" * (w * h // 2))
    f["mask_huge_dimsize"] = metaimage(os.path.join(FIXTURES, "mask_huge_dimsize.mha"), (16384, 16384, 256),
                                       "MET_UCHAR", b"\x01" * (w * h))

    # Calibrations.
    with open(XML) as g:
        xml = g.read()
    end = xml.index("/>", xml.index('<Transform From="Image" To="Probe"')) + 2
    conflicting = '\n    <Transform From="Image" To="Probe" Matrix="2 0 0 0  0 2 0 0  0 0 2 0  0 0 0 1" />'
    f["calibration_conflicting"] = write(os.path.join(FIXTURES, "calibration_conflicting.xml"),
                                         xml[:end] + conflicting + xml[end:])
    f["calibration_not_xml"] = write(os.path.join(FIXTURES, "calibration_not_xml.xml"), "<Plus><Transform")

    # Sweeps whose tracked transforms are not rigid, or whose frames are numbered twice.
    def scaled(lines):
        out = []
        for l in lines:
            if l.startswith("Seq_Frame0001_ProbeToTrackerTransform ="):
                numbers = [float(v) for v in l.split(" = ")[1].split()]
                for k in (0, 1, 2, 4, 5, 6, 8, 9, 10):
                    numbers[k] *= 1000
                l = "Seq_Frame0001_ProbeToTrackerTransform = " + " ".join(repr(v) for v in numbers)
            out.append(l)
        return out

    def far(lines):
        out = []
        for l in lines:
            if l.startswith("Seq_Frame0002_ProbeToTrackerTransform ="):
                numbers = l.split(" = ")[1].split()
                numbers[3] = "1e300"
                l = "Seq_Frame0002_ProbeToTrackerTransform = " + " ".join(numbers)
            out.append(l)
        return out

    def renumbered(lines):
        extra = [l.replace("Seq_Frame0001_", "Seq_Frame1_", 1) for l in lines
                 if l.startswith("Seq_Frame0001_ProbeToTrackerTransform =")]
        at = max(i for i, l in enumerate(lines) if l.startswith("Seq_Frame0003_"))
        return lines[: at + 1] + extra + lines[at + 1:]

    f["sweep_scaled_frame1"] = sweep_variant("sweep_scaled_frame1", scaled)
    f["sweep_far_frame2"] = sweep_variant("sweep_far_frame2", far)
    f["sweep_frame1_twice"] = sweep_variant("sweep_frame1_twice", renumbered)
    f["sweep_all_invalid"] = sweep_variant(
        "sweep_all_invalid", lambda lines: [l.replace("TransformStatus = OK", "TransformStatus = INVALID") for l in lines])
    f["sweep_dimsize_huge"] = sweep_variant("sweep_dimsize_huge", set_field("DimSize", "16384 16384 4"))
    f["sweep_fifo"] = os.path.join(FIXTURES, "pipe.igs.mha")
    os.mkfifo(f["sweep_fifo"])
    f["folder"] = os.path.join(FIXTURES, "a_folder")
    os.makedirs(f["folder"])
    return f


# ---------------------------------------------------------------------------------------------------------------
# The cases.

def cases(f):
    out = os.path.join(RESULTS, "out")
    c = []

    def case(name, args, expect, outputs=(), valid=False):
        c.append({"name": name, "args": [str(a) for a in args], "expect": expect, "outputs": list(outputs),
                  "valid": valid})

    # A valid run of each fixture that must be valid, so that the malformed ones are malformed for their defect.
    case("valid field renders", ["render", f["field"], "--plane", 0, 0, 0, 0, 0, 1, "--size", 32, 32, "-o",
                                 out + "_valid.png"], [], valid=True)
    case("valid sweep reads", ["info", SWEEP, "--calibration", XML], [], valid=True)

    # Options of `bigus train`, refused when the command line is parsed.
    train = ["train", SWEEP, "--calibration", XML, "-o", out + "_train.vtp"]
    bad_train_options = {
        "--time-budget": ["-1", "nan", "inf", "1e300", "abc"],
        "--iterations": ["-5", "abc", "1e99"],
        "--elevation-sigma": ["-1", "nan", "inf"],
        "--threads": ["-1", "nan"],
        "--holdout-every": ["-1", "nan"],
        "--holdout-offset": ["-1"],
        "--holdout-sweep": ["-2"],
        "--evaluate-every": ["-1", "nan", "inf"],
        "--max-gaussians": ["0", "-1", "nan"],
        "--initial-gaussians": ["-1"],
        "--growth-margin": ["nan", "2"],
        "--densify-percentile": ["-1", "101", "nan"],
        "--training-cutoff": ["1", "-1", "6", "nan"],
        "--residual-seeds": ["-1", "101"],
        "--merge-tolerance": ["-0.1", "2", "nan"],
        "--coarse-fraction": ["nan", "1.5", "-0.5"],
        "--frames-per-step": ["0", "5000"],
        "--pose-smoothness": ["-1", "nan"],
        "--pose-refinement-start": ["nan", "2", "-3"],
        "--solve-iterations": ["0", "nan"],
        "--solve-memory": ["-1", "nan"],
        "--solve-l1": ["2", "inf"],
    }
    for option, values in bad_train_options.items():
        for value in values:
            case("train %s %s" % (option, value), train + [option, value], [option], [out + "_train.vtp"])
    for weights in (["1", "nan", "0"], ["1", "-1", "0"], ["1", "0"], ["200", "0", "0"], ["0", "0", "0"]):
        case("train --loss-weights " + " ".join(weights), train + ["--loss-weights"] + weights, ["--loss-weights"],
             [out + "_train.vtp"])
    case("train --checkpoint-interval -1", train + ["--checkpoint", out + ".ckpt", "--checkpoint-interval", "-1"],
         ["--checkpoint-interval"], [out + "_train.vtp", out + ".ckpt"])
    case("train --checkpoint-interval without --checkpoint", train + ["--checkpoint-interval", "5"],
         ["--checkpoint"], [out + "_train.vtp"])

    # `bigus train` on malformed inputs: refused before training.
    case("train holdout offset past every", train + ["--holdout-every", 2, "--holdout-offset", 7],
         ["HoldOutOffset 7 must be below HoldOutEvery 2"], [out + "_train.vtp"])
    case("train output is the sweep", ["train", SWEEP, "--calibration", XML, "-o", SWEEP], ["input"])
    case("train output folder missing", ["train", SWEEP, "--calibration", XML, "-o",
                                         os.path.join(RESULTS, "missing", "f.vtp")], ["missing"])
    case("train output is a folder", ["train", SWEEP, "--calibration", XML, "-o", f["folder"]], ["folder"])
    for name, expect in [("mask_nan", "not finite"), ("mask_inf_pixel", "not finite at pixel 199, 149"),
                         ("mask_wrong_size", "mask"), ("mask_truncated", "the file holds"),
                         ("mask_huge_dimsize", "16384 x 16384 x 256")]:
        case("train " + name, train + ["--mask", f[name]], [expect], [out + "_train.vtp"])
    case("train mask is a pipe", train + ["--mask", f["fifo"]], ["not a regular file"], [out + "_train.vtp"])
    case("train every frame INVALID", ["train", f["sweep_all_invalid"], "--calibration", XML, "-o", out + "_train.vtp"],
         ["every one of its 4 frames is marked INVALID"], [out + "_train.vtp"])
    case("train conflicting calibration", ["train", SWEEP, "--calibration", f["calibration_conflicting"], "-o",
                                           out + "_train.vtp"], ["conflicts with"], [out + "_train.vtp"])
    case("train calibration not XML", ["train", SWEEP, "--calibration", f["calibration_not_xml"], "-o",
                                       out + "_train.vtp"], ["calibration_not_xml.xml"], [out + "_train.vtp"])
    for name, expect in [("sweep_scaled_frame1", "frame 1: field Seq_Frame0001_ProbeToTrackerTransform is not rigid"),
                         ("sweep_far_frame2", "frame 2: field Seq_Frame0002_ProbeToTrackerTransform is not rigid"),
                         ("sweep_frame1_twice", "a second time"),
                         ("sweep_dimsize_huge", "needs"),
                         ("sweep_fifo", "pipe")]:
        for command in (["info", f[name], "--calibration", XML],
                        ["train", f[name], "--calibration", XML, "-o", out + "_train.vtp"]):
            case("%s %s" % (command[0], name), command, [expect], [out + "_train.vtp"])

    # Every file of the reader's own corpus (Testing/Data/Malformed; its README says what is wrong with each, and
    # which files are valid variants that must read).
    valid = {"valid_4frames.igs.mha", "orientation_uf.igs.mha", "orientation_mn.igs.mha", "orientation_un.igs.mha",
             "invalid_status_frame1.igs.mha", "copy_uncompressed.mhd", "copy_compressed.mhd",
             "crlf_compressed.mhd", "padded_values.igs.mha", "crlf.igs.mha", "imagetoreference_direct.igs.mha"}
    for name in sorted(os.listdir(MALFORMED)):
        if not name.endswith((".mha", ".mhd")):
            continue
        calibration = [] if name == "imagetoreference_direct.igs.mha" else ["--calibration", XML]
        case("info Malformed/" + name, ["info", os.path.join(MALFORMED, name)] + calibration, [name],
             valid=name in valid)

    # Malformed fields, given to every command that reads one.
    fields = ["field_nan_reflectivity", "field_inf_reflectivity", "field_zero_quaternion", "field_nan_quaternion",
              "field_zero_scale", "field_negative_scale", "field_huge_scale", "field_nan_position",
              "field_far_position", "field_claims_1e11_points", "field_truncated", "field_empty", "field_not_xml",
              "field_without_scale", "field_binary_garbage", "fifo"]
    expects = {"field_nan_reflectivity": "Gaussian 4 has a Reflectivity", "field_inf_reflectivity":
               "Gaussian 2 has a Reflectivity", "field_zero_quaternion": "Gaussian 3 has a Rotation",
               "field_nan_quaternion": "Gaussian 1 has a Rotation", "field_zero_scale": "Gaussian 5",
               "field_negative_scale": "Gaussian 0", "field_huge_scale": "Gaussian 6", "field_nan_position":
               "Gaussian 7", "field_far_position": "Gaussian 8", "field_claims_1e11_points": "100000000000 Gaussians",
               "fifo": "not a regular file"}
    for name in fields:
        expect = [expects.get(name, os.path.basename(f[name]))]
        for command, extra in [("render", ["--plane", 0, 0, 0, 0, 0, 1, "--size", 32, 32, "-o", out + "_r.png"]),
                               ("merge", ["-o", out + "_m.vtp"]),
                               ("fill-gaps", ["-o", out + "_g.vtp"]),
                               ("evaluate", [SWEEP, "--calibration", XML, "--report", out + "_report"])]:
            case("%s %s" % (command, name), [command, f[name]] + extra, expect,
                 [out + "_r.png", out + "_m.vtp", out + "_g.vtp", out + "_report"])

    # `bigus render`: sizes and spacings refused before anything is allocated.
    plane = ["render", f["field"], "--plane", 0, 0, 0, 0, 0, 1, "-o", out + "_r.png"]
    for option, values in {"--spacing": ["0", "-1", "nan", "inf"],
                           "--size": [("0", "0"), ("-5", "10"), ("100000", "100000"), ("nan", "5")]}.items():
        for value in values:
            value = list(value) if isinstance(value, tuple) else [value]
            case("render %s %s" % (option, " ".join(value)), plane + [option] + value, [option], [out + "_r.png"])
    case("render --plane nan", ["render", f["field"], "--plane", "nan", 0, 0, 0, 0, 1, "-o", out + "_r.png"],
         ["--plane"], [out + "_r.png"])
    case("render --plane zero normal", ["render", f["field"], "--plane", 0, 0, 0, 0, 0, 0, "-o", out + "_r.png"],
         ["normal"], [out + "_r.png"])
    case("render --volume --spacing 1e-5", ["render", f["field"], "--volume", "--spacing", "1e-5", "-o",
                                            out + "_v.vti"], ["MB"], [out + "_v.vti"])
    case("render output is the field", ["render", f["field"], "--plane", 0, 0, 0, 0, 0, 1, "-o", f["field"]],
         ["input"])

    # `bigus evaluate`, `sweep`, `merge`, `fill-gaps` options.
    evaluate = ["evaluate", f["field"], SWEEP, "--calibration", XML, "--report", out + "_report"]
    case("evaluate holdout offset past every", evaluate + ["--holdout-every", 2, "--holdout-offset", 7],
         ["--holdout-offset 7 must be below --holdout-every 2"], [out + "_report"])
    case("evaluate --holdout-every -1", evaluate + ["--holdout-every", "-1"], ["--holdout-every"], [out + "_report"])
    case("evaluate --refine-steps 0", evaluate + ["--refine-steps", "0"], ["--refine-steps"], [out + "_report"])
    sweep = ["sweep", SWEEP, "-o", out + "_s.igs.mha"]
    for option, value in [("--frames", "0"), ("--axis", "3"), ("--offset", "1.5"), ("--tilt", "95"),
                          ("--spacing", "-1"), ("--spacing", "nan")]:
        case("sweep %s %s" % (option, value), sweep + [option, value], [option], [out + "_s.igs.mha"])
    merge = ["merge", f["field"], "-o", out + "_m.vtp"]
    for option, value in [("--tolerance", "0"), ("--tolerance", "nan"), ("--tolerance", "2"),
                          ("--neighbours", "0"), ("--neighbours", "100")]:
        case("merge %s %s" % (option, value), merge + [option, value], [option], [out + "_m.vtp"])
    gaps = ["fill-gaps", f["field"], "-o", out + "_g.vtp"]
    for option, value in [("--minimum-gap", "0"), ("--minimum-gap", "nan"), ("--clearance", "-1"),
                          ("--max-gaussians", "-1")]:
        case("fill-gaps %s %s" % (option, value), gaps + [option, value], [option], [out + "_g.vtp"])
    return c


# ---------------------------------------------------------------------------------------------------------------

def digest(path):
    if os.path.isdir(path):
        return ("folder", tuple(sorted(os.listdir(path))))
    if not os.path.isfile(path):
        return ("special", os.stat(path).st_mode)
    with open(path, "rb") as f:
        return ("file", hashlib.sha256(f.read()).hexdigest())


def run_case(case):
    named = [a for a in case["args"] if os.path.exists(a)]
    before = {a: digest(a) for a in named}
    outputs_before = {o: os.path.exists(o) for o in case["outputs"]}
    start = time.time()
    try:
        result = subprocess.run([BIGUS] + case["args"], capture_output=True, text=True, timeout=TIMEOUT,
                                errors="replace", stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return "hang: no answer within %.0f s" % TIMEOUT, time.time() - start, ""
    seconds = time.time() - start
    stderr = result.stderr.strip()
    problems = []
    code = result.returncode
    if code < 0:
        problems.append("crash: killed by signal %d" % -code)
    elif case["valid"] and code != 0:
        problems.append("exit %d for a valid input" % code)
    elif not case["valid"] and code not in (1, 2):
        problems.append("exit %d (a refusal is 1 or 2)" % code)
    for marker in ("terminate called", "bad_alloc", "Segmentation", "AddressSanitizer", "runtime error:",
                   "LeakSanitizer"):
        if marker in result.stderr or marker in result.stdout:
            problems.append("stderr shows '%s'" % marker)
    if not case["valid"]:
        if not stderr:
            problems.append("no message on stderr")
        for text in case["expect"]:
            if text.lower() not in stderr.lower():
                problems.append("the message does not say '%s'" % text)
    for a, d in before.items():
        if not os.path.exists(a) or digest(a) != d:
            problems.append("the input %s changed" % a)
    for o, existed in outputs_before.items():
        if not existed and os.path.exists(o) and not case["valid"]:
            problems.append("left %s behind" % o)
            shutil.rmtree(o) if os.path.isdir(o) else os.remove(o)
    return "; ".join(problems), seconds, stderr.split("\n")[0] if stderr else ""


def main():
    fixtures = make_fixtures()
    all_cases = cases(fixtures)
    failures = 0
    total = 0.0
    for k, case in enumerate(all_cases):
        problem, seconds, message = run_case(case)
        total += seconds
        status = "FAIL" if problem else "ok"
        print("%3d %-4s %5.1f s  %-52s %s" % (k + 1, status, seconds, case["name"][:52],
                                            problem if problem else message[:150]))
        sys.stdout.flush()
        failures += bool(problem)
    print("%d cases in %.0f s: %d failed" % (len(all_cases), total, failures))
    return 1 if failures or len(all_cases) < 150 else 0


if __name__ == "__main__":
    sys.exit(main())

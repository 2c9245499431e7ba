#!/usr/bin/env python3
"""Generate the malformed (and a few well-formed) sequence metafiles of Testing/Data/Malformed.

Every file is derived from the real PLUS fixture
Testing/Data/nwire-phantom/NwirePhantomFreehandCropped.igs.mha (200 x 150 pixels, 20 frames,
MET_UCHAR, zlib-compressed, per-frame ProbeToTracker, ReferenceToTracker and StylusToTracker
transforms; ImageToProbe is in PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml).
The script parses the fixture's header and body itself, applies one defect per file and writes the
result next to itself. Most files keep only the first 4 frames; the uncompressed ones with a defect
keep only a 40 x 30 crop of those frames, to keep the corpus small.

Run with any Python 3 (standard library only):   python3 make_corpus.py
The output is deterministic for a given zlib; the generated files are committed, so the tests never
run this script. README.md lists every file, its defect and the error the reader must report;
Testing/Cxx/TestMalformedSequences.cxx checks exactly that.
"""
import math
import os
import re
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.dirname(HERE)
SOURCE = os.path.join(DATA, "nwire-phantom", "NwirePhantomFreehandCropped.igs.mha")
CALIBRATION = os.path.join(
    DATA, "nwire-phantom", "PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml")

FRAME_KEY = re.compile(r"^Seq_Frame(\d+)_(.+)$")


# ----------------------------------------------------------------------------------------------
# Source fixture
# ----------------------------------------------------------------------------------------------
class Source:
    """Header fields (in file order) and inflated pixels of the fixture."""

    def __init__(self, path):
        data = open(path, "rb").read()
        m = re.search(rb"^ElementDataFile[ \t]*=[^\n]*\n", data, re.M)
        if not m:
            raise SystemExit(path + ": no ElementDataFile line")
        self.fields = []  # [key, value]
        for line in data[:m.end()].decode("ascii").splitlines():
            if not line.strip():
                continue
            key, value = line.split("=", 1)
            self.fields.append([key.strip(), value.strip()])
        body = data[m.end():]
        declared = int(self.get("CompressedDataSize"))
        if declared != len(body):
            raise SystemExit(path + ": CompressedDataSize %d but %d bytes follow" % (declared, len(body)))
        self.width, self.height, self.frames = [int(v) for v in self.get("DimSize").split()]
        self.pixels = zlib.decompress(body)
        if len(self.pixels) != self.width * self.height * self.frames:
            raise SystemExit(path + ": body does not hold DimSize pixels")

    def get(self, key):
        for k, v in self.fields:
            if k == key:
                return v
        return None


SRC = Source(SOURCE)
W, H = SRC.width, SRC.height
FRAME_BYTES = W * H


def frame_pixels(frames):
    return SRC.pixels[:frames * FRAME_BYTES]


def base_fields(frames):
    """Global fields plus the per-frame fields of frames 0..frames-1, DimSize adjusted, no
    ElementDataFile / CompressedDataSize (write_* add them)."""
    out = []
    for key, value in SRC.fields:
        m = FRAME_KEY.match(key)
        if m and int(m.group(1)) >= frames:
            continue
        if key in ("ElementDataFile", "CompressedDataSize"):
            continue
        if key == "DimSize":
            value = "%d %d %d" % (W, H, frames)
        out.append([key, value])
    return out


# ----------------------------------------------------------------------------------------------
# Field editing helpers
# ----------------------------------------------------------------------------------------------
def frame_key(k, field):
    return "Seq_Frame%04d_%s" % (k, field)


def index_of(fields, key):
    for i, (k, _) in enumerate(fields):
        if k == key:
            return i
    raise KeyError(key)


def get(fields, key):
    return fields[index_of(fields, key)][1]


def set_field(fields, key, value):
    fields[index_of(fields, key)][1] = value


def remove(fields, key):
    del fields[index_of(fields, key)]


def insert_after(fields, after_key, key, value):
    fields.insert(index_of(fields, after_key) + 1, [key, value])


def matrix(text):
    values = [float(v) for v in text.split()]
    assert len(values) == 16
    return values


def matrix_text(m):
    return " ".join(repr(float(v)) if v != int(v) else str(int(v)) for v in m)


def multiply(a, b):
    return [sum(a[4 * i + k] * b[4 * k + j] for k in range(4)) for i in range(4) for j in range(4)]


def invert_affine(m):
    a, b, c, d, e, f, g, h, k = m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]
    det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
    r = [(e * k - f * h) / det, (c * h - b * k) / det, (b * f - c * e) / det, 0,
         (f * g - d * k) / det, (a * k - c * g) / det, (c * d - a * f) / det, 0,
         (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det, 0,
         0, 0, 0, 1]
    for i in range(3):
        r[4 * i + 3] = -(r[4 * i] * m[3] + r[4 * i + 1] * m[7] + r[4 * i + 2] * m[11])
    return r


def image_to_probe():
    xml = open(CALIBRATION).read()
    m = re.search(r'<Transform\s+From="Image"\s+To="Probe"\s+Matrix="([^"]*)"', xml)
    return matrix(m.group(1))


def image_to_reference(fields, k):
    """inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe of frame k."""
    probe = matrix(get(fields, frame_key(k, "ProbeToTrackerTransform")))
    reference = matrix(get(fields, frame_key(k, "ReferenceToTrackerTransform")))
    return multiply(multiply(invert_affine(reference), probe), image_to_probe())


def flip(pixels, width, height, frames, columns, rows):
    out = bytearray()
    for f in range(frames):
        for j in range(height):
            src = (height - 1 - j) if rows else j
            row = pixels[(f * height + src) * width:(f * height + src + 1) * width]
            out += row[::-1] if columns else row
    return bytes(out)


def crop(pixels, frames, x0, y0, width, height):
    out = bytearray()
    for f in range(frames):
        for j in range(y0, y0 + height):
            start = f * FRAME_BYTES + j * W + x0
            out += pixels[start:start + width]
    return bytes(out)


# ----------------------------------------------------------------------------------------------
# Writers
# ----------------------------------------------------------------------------------------------
def render(fields, eol="\n", fmt="{} = {}"):
    return "".join(fmt.format(k, v) + eol for k, v in fields).encode("latin-1")


def write(name, data):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)
    WRITTEN.append(name)


def with_storage(fields, compressed, size=None, data_file="LOCAL"):
    """Copy of fields with CompressedData, CompressedDataSize and ElementDataFile set."""
    out = [list(f) for f in fields if f[0] not in ("CompressedData", "CompressedDataSize",
                                                    "ElementDataFile")]
    i = index_of(out, "BinaryDataByteOrderMSB") + 1
    out.insert(i, ["CompressedData", "True" if compressed else "False"])
    if compressed and size is not None:
        out.insert(i + 1, ["CompressedDataSize", str(size)])
    out.append(["ElementDataFile", data_file])
    return out


def write_mha(name, fields, pixels, compressed=True, body=None, declared_size=None, **render_args):
    """Header + pixels in one file. body overrides the (compressed) bytes written after the header;
    declared_size overrides CompressedDataSize (None: the size of the compressed pixels, "omit":
    no CompressedDataSize field)."""
    stored = zlib.compress(pixels, 9) if compressed else pixels
    size = len(stored) if declared_size is None else declared_size
    header = with_storage(fields, compressed, None if size == "omit" else size)
    write(name, render(header, **render_args) + (stored if body is None else body(stored)))


def write_mhd(name, fields, pixels, data_file, compressed, write_data=True, data_bytes=None,
              **render_args):
    stored = zlib.compress(pixels, 9) if compressed else pixels
    if data_bytes is not None:
        stored = data_bytes(stored)
    header = with_storage(fields, compressed, len(stored) if compressed else None, data_file)
    write(name, render(header, **render_args))
    if write_data:
        write(data_file, stored)


WRITTEN = []


def invert16(data, offset):
    return data[:offset] + bytes(x ^ 0xFF for x in data[offset:offset + 16]) + data[offset + 16:]


def find_corruption(stored, expected, wanted):
    """(offset, zlib message, bytes inflated before the error) of the offset nearest the middle of
    @p stored whose invert16() makes zlib fail (with a message accepted by @p wanted) before it
    has produced more than @p expected bytes."""
    middle = len(stored) // 2
    for distance in range(middle - 16):
        for offset in (middle - distance, middle + distance):
            data = invert16(stored, offset)
            inflater = zlib.decompressobj()
            produced = 0
            for k in range(len(data)):
                try:
                    produced += len(inflater.decompress(data[k:k + 1]))
                except zlib.error as e:
                    message = str(e).split(": ", 1)[-1]
                    if wanted(message):
                        return offset, message, produced
                    break
                if produced > expected or inflater.eof:
                    break
    raise SystemExit("no suitable corruption found")


# ----------------------------------------------------------------------------------------------
# Corpus
# ----------------------------------------------------------------------------------------------
def main():
    for name in os.listdir(HERE):
        if name.endswith((".mha", ".mhd", ".raw", ".zraw")):
            os.remove(os.path.join(HERE, name))

    N = 4
    pixels = frame_pixels(N)

    # --- well-formed references ---------------------------------------------------------------
    valid = base_fields(N)
    write_mha("valid_4frames.igs.mha", valid, pixels)

    # Same pixels stored in the other PLUS orientations (the reader must flip them back to MF).
    for code, columns, rows in (("UF", True, False), ("MN", False, True), ("UN", True, True)):
        f = base_fields(N)
        set_field(f, "UltrasoundImageOrientation", code)
        write_mha("orientation_%s.igs.mha" % code.lower(), f, flip(pixels, W, H, N, columns, rows))

    f = base_fields(N)
    set_field(f, frame_key(1, "ProbeToTrackerTransformStatus"), "INVALID")
    write_mha("invalid_status_frame1.igs.mha", f, pixels)

    # Detached bodies: 4 frames uncompressed (.raw), all 20 frames compressed (.zraw).
    write_mhd("copy_uncompressed.mhd", valid, pixels, "copy_uncompressed.raw", compressed=False)
    write_mhd("copy_compressed.mhd", base_fields(SRC.frames), SRC.pixels, "copy_compressed.zraw",
              compressed=True)
    # CRLF header naming the same .zraw (the '\r' must not end up in the file name).
    write_mhd("crlf_compressed.mhd", base_fields(SRC.frames), SRC.pixels, "copy_compressed.zraw",
              compressed=True, write_data=False, eol="\r\n")

    write_mha("padded_values.igs.mha", valid, pixels, fmt="{}  =   {} \t  ")
    write_mha("crlf.igs.mha", valid, pixels, eol="\r\n")

    # Per-frame ImageToReferenceTransform (the automatic chain then uses it directly).
    direct = base_fields(N)
    for k in range(N):
        insert_after(direct, frame_key(k, "ImageStatus"), frame_key(k, "ImageToReferenceTransform"),
                     matrix_text(image_to_reference(direct, k)))
        insert_after(direct, frame_key(k, "ImageToReferenceTransform"),
                     frame_key(k, "ImageToReferenceTransformStatus"), "OK")
    write_mha("imagetoreference_direct.igs.mha", direct, pixels)

    # --- defective files ----------------------------------------------------------------------
    write("empty_file.igs.mha", b"")

    whole = render(with_storage(valid, True, len(zlib.compress(pixels, 9)))) + zlib.compress(pixels, 9)
    cut = whole.index(frame_key(2, "ReferenceToTrackerTransform").encode())
    write("truncated_header.igs.mha", whole[:cut + 20])  # ends inside a line
    write("truncated_header_at_line.igs.mha", whole[:cut])  # ends after a complete line

    write_mha("truncated_body.igs.mha", valid, pixels, body=lambda b: b[:len(b) // 2])
    write_mha("truncated_body_no_size.igs.mha", valid, pixels, declared_size="omit",
              body=lambda b: b[:len(b) // 2])

    # Corrupt bodies: 16 bytes inverted at the offset nearest to the middle of the zlib stream for
    # which zlib reports an error before more than the 4 frames come out (many inversions in this
    # very compressible stream just inflate to other pixels). One breaks the deflate data itself,
    # one only the Adler-32 check at the end of the stream.
    stored = zlib.compress(pixels, 9)
    for name, wanted in (("corrupt_body.igs.mha", lambda e: "data check" not in e),
                         ("corrupt_checksum.igs.mha", lambda e: "data check" in e)):
        offset, message, produced = find_corruption(stored, len(pixels), wanted)
        print("%s: bytes %d-%d of %d inverted; zlib: %s after %d bytes (frame %d)" % (
            name, offset, offset + 15, len(stored), message, produced, produced // FRAME_BYTES))
        write_mha(name, valid, pixels, body=lambda b, o=offset: invert16(b, o))

    write_mha("compressed_size_too_large.igs.mha", valid, pixels,
              declared_size=len(zlib.compress(pixels, 9)) + 1000)

    for name, height in (("dimsize_larger_compressed.igs.mha", H + 1),
                         ("dimsize_smaller_compressed.igs.mha", H - 1)):
        f = base_fields(N)
        set_field(f, "DimSize", "%d %d %d" % (W, height, N))
        write_mha(name, f, pixels)

    # Uncompressed defects use a 40 x 30 crop of the 4 frames (pixel values do not matter there).
    CW, CH = 40, 30
    small = crop(pixels, N, 80, 60, CW, CH)
    for name, height in (("dimsize_larger_uncompressed.mha", CH + 1),
                         ("dimsize_smaller_uncompressed.mha", CH - 1)):
        f = base_fields(N)
        set_field(f, "DimSize", "%d %d %d" % (CW, height, N))
        write_mha(name, f, small, compressed=False)

    for name, value in (("elementtype_long_long.igs.mha", "MET_LONG_LONG"),
                        ("elementtype_garbage.igs.mha", "\x01\xfe\x7fgarbage")):
        f = base_fields(N)
        set_field(f, "ElementType", value)
        write_mha(name, f, pixels)

    f = base_fields(N)
    remove(f, "NDims")
    write_mha("missing_ndims.igs.mha", f, pixels)

    f = base_fields(N)
    set_field(f, "NDims", "4")
    write_mha("ndims_4.igs.mha", f, pixels)

    f = base_fields(N)
    remove(f, "DimSize")
    write_mha("missing_dimsize.igs.mha", f, pixels)

    f = base_fields(N)
    set_field(f, "DimSize", "200 one-fifty 4")
    write_mha("dimsize_not_numeric.igs.mha", f, pixels)

    f = base_fields(N)
    remove(f, frame_key(2, "ProbeToTrackerTransform"))
    write_mha("missing_transform_frame2.igs.mha", f, pixels)

    def edit_matrix(name, k, transform, edit):
        f = base_fields(N)
        key = frame_key(k, transform)
        values = get(f, key).split()
        set_field(f, key, " ".join(edit(values)))
        write_mha(name, f, pixels)

    edit_matrix("transform_not_numeric_frame1.igs.mha", 1, "ProbeToTrackerTransform",
                lambda v: v[:3] + ["abc"] + v[4:])
    edit_matrix("transform_comma_decimal_frame3.igs.mha", 3, "ProbeToTrackerTransform",
                lambda v: v[:3] + [v[3].replace(".", ",")] + v[4:])
    edit_matrix("transform_15_numbers_frame3.igs.mha", 3, "ProbeToTrackerTransform", lambda v: v[:15])
    edit_matrix("transform_17_numbers_frame0.igs.mha", 0, "ReferenceToTrackerTransform",
                lambda v: v + ["1"])
    edit_matrix("transform_nan_frame3.igs.mha", 3, "ProbeToTrackerTransform",
                lambda v: v[:5] + ["nan"] + v[6:])
    edit_matrix("transform_inf_frame2.igs.mha", 2, "ReferenceToTrackerTransform",
                lambda v: v[:7] + ["-inf"] + v[8:])
    edit_matrix("transform_overflow_frame1.igs.mha", 1, "ProbeToTrackerTransform",
                lambda v: ["1e999"] + v[1:])
    zero3x3 = lambda v: ["0", "0", "0", v[3], "0", "0", "0", v[7], "0", "0", "0", v[11]] + v[12:]
    edit_matrix("singular_probe_frame2.igs.mha", 2, "ProbeToTrackerTransform", zero3x3)
    edit_matrix("singular_reference_frame1.igs.mha", 1, "ReferenceToTrackerTransform", zero3x3)

    # ImageToReference of frame 2 with its row axis turned 20 degrees towards the column axis.
    sheared = [list(x) for x in direct]
    key = frame_key(2, "ImageToReferenceTransform")
    m = matrix(get(sheared, key))
    u = [m[0], m[4], m[8]]
    v = [m[1], m[5], m[9]]
    nu = math.sqrt(sum(x * x for x in u))
    nv = math.sqrt(sum(x * x for x in v))
    # Orthonormalise v against u first, then tilt it by 20 degrees towards u.
    uh = [x / nu for x in u]
    w = [v[i] - sum(v[j] * uh[j] for j in range(3)) * uh[i] for i in range(3)]
    nw = math.sqrt(sum(x * x for x in w))
    wh = [x / nw for x in w]
    a = math.radians(20.0)
    v2 = [nv * (math.cos(a) * wh[i] + math.sin(a) * uh[i]) for i in range(3)]
    m[1], m[5], m[9] = v2
    set_field(sheared, key, matrix_text(m))
    write_mha("sheared_imagetoreference_frame2.igs.mha", sheared, pixels)

    f = base_fields(N)
    set_field(f, frame_key(1, "ProbeToTrackerTransformStatus"), "MAYBE")
    write_mha("status_maybe_frame1.igs.mha", f, pixels)

    f = base_fields(N)
    set_field(f, frame_key(2, "ImageStatus"), "MAYBE")
    write_mha("imagestatus_maybe_frame2.igs.mha", f, pixels)

    # No ElementDataFile line: in an .mha the compressed body follows the last frame field.
    header = with_storage(valid, True, len(zlib.compress(pixels, 9)))
    remove(header, "ElementDataFile")
    write("missing_elementdatafile.igs.mha", render(header) + zlib.compress(pixels, 9))
    write("missing_elementdatafile.mhd", render(header))

    write_mhd("missing_raw.mhd", valid, pixels, "missing_raw_does_not_exist.raw", compressed=False,
              write_data=False)

    f = base_fields(N)
    set_field(f, "DimSize", "%d %d %d" % (CW, CH, N))
    write_mhd("short_raw.mhd", f, small, "short_raw.raw", compressed=False,
              data_bytes=lambda b: b[:len(b) - CW * CH // 2])

    # "UltrasoundImageType BRIGHTNESS": the '=' is missing.
    fields = base_fields(N)
    stored = zlib.compress(pixels, 9)
    text = render(with_storage(fields, True, len(stored))).replace(
        b"UltrasoundImageType = BRIGHTNESS", b"UltrasoundImageType BRIGHTNESS")
    write("line_without_equals.igs.mha", text + stored)

    f = base_fields(N)
    insert_after(f, "ElementType", "DimSize", "200 150 2")
    write_mha("duplicated_field.igs.mha", f, pixels)

    f = base_fields(N)
    key = frame_key(1, "ProbeToTrackerTransform")
    insert_after(f, frame_key(1, "Timestamp"), key, get(f, key))
    write_mha("duplicated_frame_field.igs.mha", f, pixels)

    # Header with the fields of 5 frames but DimSize (and the body) of 4.
    f = base_fields(N + 1)
    set_field(f, "DimSize", "%d %d %d" % (W, H, N))
    write_mha("frame_beyond_dimsize.igs.mha", f, pixels)

    f = base_fields(N)
    set_field(f, "UltrasoundImageOrientation", "FM")
    write_mha("orientation_fm.igs.mha", f, pixels)

    for name in sorted(set(WRITTEN)):
        print("%-45s %8d bytes" % (name, os.path.getsize(os.path.join(HERE, name))))


if __name__ == "__main__":
    main()

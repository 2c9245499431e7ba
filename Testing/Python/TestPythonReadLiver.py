"""/usr/bin/python3 imports bigus next to vtk, reads the liver sweep and checks frames and poses.

Usage: TestPythonReadLiver.py TESTING_DATA_DIR EXAMPLE_DATA_DIR
"""
import math
import os
import sys

import vtk  # noqa: F401  (bigus must import next to Debian's VTK)
import bigus


def main():
    example_data = sys.argv[2]
    reader = bigus.vtkUltrasoundSequenceReader()
    reader.SetFileName(os.path.join(example_data, "liver", "liver_sweep.igs.mha"))
    reader.Update()
    assert reader.GetLastErrorText() == "", reader.GetLastErrorText()
    frames = reader.GetOutput()
    assert frames.GetDimensions() == (739, 593, 140), frames.GetDimensions()
    poses = frames.GetFieldData().GetArray("ImageToReference")
    assert poses.GetNumberOfTuples() == 140 and poses.GetNumberOfComponents() == 16
    geometry = bigus.vtkUltrasoundSliceGeometry()
    matrix = vtk.vtkMatrix4x4()
    for k in range(140):
        matrix.DeepCopy(poses.GetTuple(k))
        geometry.SetImageToReference(matrix)
        assert geometry.GetStatus() == 0, (k, geometry.GetStatusText())
        for spacing in geometry.GetPixelSpacing():
            assert abs(spacing - 0.3148) < 5e-5, (k, spacing)
        u, v, n = geometry.GetAxisU(), geometry.GetAxisV(), geometry.GetNormal()
        assert abs(sum(a * b for a, b in zip(u, v))) < 1e-6, k
        assert abs(math.sqrt(sum(a * a for a in n)) - 1) < 1e-12, k
    # The first pose as stored in the file (Seq_Frame0000_ImageToReferenceTransform).
    first = poses.GetTuple(0)
    assert first[3] == -170.668461 and first[11] == 162.324848, first
    valid = frames.GetFieldData().GetArray("FrameValid")
    assert all(valid.GetValue(k) == 1 for k in range(140))
    # The pixels of frame 70 are those of VTK's own MetaIO reader (an independent decoder).
    metaio = vtk.vtkMetaImageReader()
    metaio.SetFileName(os.path.join(example_data, "liver", "liver_sweep.igs.mha"))
    metaio.Update()
    ours, theirs = frames.GetPointData().GetScalars(), metaio.GetOutput().GetPointData().GetScalars()
    offset = 70 * 739 * 593
    for p in range(0, 739 * 593, 997):
        assert ours.GetValue(offset + p) == theirs.GetValue(offset + p), p
    print("liver sweep read from Python: 140 frames of 739 x 593, spacing 0.3148 mm, poses orthonormal")


if __name__ == "__main__":
    main()

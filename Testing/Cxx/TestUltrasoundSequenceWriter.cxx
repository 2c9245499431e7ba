// vtkUltrasoundSequenceWriter: write-read round trips are exact, VTK's own MetaIO reader (an independent
// implementation of the format) sees the same pixels, and a failed write leaves existing files alone.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkImageData.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkUltrasoundSequenceWriter.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <fstream>

using bigus_test::DataPath;
using bigus_test::OutputPath;
using bigus_test::Pose;

namespace
{
vtkSmartPointer<vtkImageData> ReadSpine()
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(DataPath("spine-phantom/SpinePhantomFreehand.igs.mha").c_str());
  reader->SetCalibrationFileName(
    DataPath("spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml").c_str());
  reader->Update();
  EXPECT_STREQ(reader->GetLastErrorText(), "");
  vtkSmartPointer<vtkImageData> copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(reader->GetOutput());
  return copy;
}

vtkSmartPointer<vtkImageData> WriteThenRead(vtkImageData* sequence, const std::string& file, bool compress)
{
  std::remove(file.c_str());
  vtkNew<vtkUltrasoundSequenceWriter> writer;
  writer->SetInputData(sequence);
  writer->SetFileName(file.c_str());
  writer->SetUseCompression(compress);
  EXPECT_EQ(writer->Write(), 1);
  EXPECT_STREQ(writer->GetLastErrorText(), "");
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(file.c_str());
  reader->Update();
  EXPECT_STREQ(reader->GetLastErrorText(), "") << file;
  vtkSmartPointer<vtkImageData> copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(reader->GetOutput());
  return copy;
}

void ExpectIdentical(vtkImageData* a, vtkImageData* b)
{
  int da[3], db[3];
  a->GetDimensions(da);
  b->GetDimensions(db);
  ASSERT_EQ(std::vector<int>(da, da + 3), std::vector<int>(db, db + 3));
  ASSERT_EQ(a->GetScalarType(), b->GetScalarType());
  const std::size_t bytes = std::size_t(da[0]) * da[1] * da[2] * a->GetScalarSize();
  EXPECT_EQ(std::memcmp(a->GetScalarPointer(), b->GetScalarPointer(), bytes), 0);
  for (const char* name : { "ImageToReference", "Timestamp", "FrameValid" })
  {
    vtkDataArray* x = a->GetFieldData()->GetArray(name);
    vtkDataArray* y = b->GetFieldData()->GetArray(name);
    ASSERT_TRUE(x && y) << name;
    ASSERT_EQ(x->GetNumberOfValues(), y->GetNumberOfValues()) << name;
    for (vtkIdType v = 0; v < x->GetNumberOfValues(); ++v)
    {
      // Bit-exact: the writer prints the shortest decimal that reads back to the same double.
      EXPECT_EQ(x->GetVariantValue(v).ToDouble(), y->GetVariantValue(v).ToDouble()) << name << " value " << v;
    }
  }
}
}

TEST(SequenceWriter, RoundTripIsExactInEveryLayout)
{
  vtkSmartPointer<vtkImageData> spine = ReadSpine();
  ExpectIdentical(spine, WriteThenRead(spine, OutputPath("roundtrip.igs.mha"), true));
  ExpectIdentical(spine, WriteThenRead(spine, OutputPath("roundtrip_raw.igs.mha"), false));
  ExpectIdentical(spine, WriteThenRead(spine, OutputPath("roundtrip_detached.mhd"), false));
  ExpectIdentical(spine, WriteThenRead(spine, OutputPath("roundtrip_zdetached.mhd"), true));
  std::ifstream raw(OutputPath("roundtrip_detached.raw"));
  EXPECT_TRUE(raw.good()) << "the .mhd body goes to a .raw beside it";
  std::ifstream zraw(OutputPath("roundtrip_zdetached.zraw"));
  EXPECT_TRUE(zraw.good()) << "a compressed .mhd body goes to a .zraw beside it";
}

TEST(SequenceWriter, FloatFramesAndInvalidFramesRoundTrip)
{
  vtkSmartPointer<vtkImageData> spine = ReadSpine();
  vtkNew<vtkFloatArray> values;
  values->SetName("Intensity");
  vtkDataArray* bytes = spine->GetPointData()->GetScalars();
  values->SetNumberOfTuples(bytes->GetNumberOfTuples());
  for (vtkIdType i = 0; i < bytes->GetNumberOfTuples(); ++i)
  {
    values->SetValue(i, static_cast<float>(bytes->GetTuple1(i) / 255.0 - 0.1 * (i % 7)));
  }
  spine->GetPointData()->SetScalars(values);
  // An invalid frame is written with status INVALID; the reader gives it FrameValid 0 and the
  // identity as ImageToReference (its pose is never used).
  spine->GetFieldData()->GetArray("FrameValid")->SetTuple1(4, 0);
  vtkSmartPointer<vtkImageData> back = WriteThenRead(spine, OutputPath("float.igs.mha"), true);
  EXPECT_EQ(back->GetFieldData()->GetArray("FrameValid")->GetTuple1(4), 0);
  const double identity[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
  for (int e = 0; e < 16; ++e)
  {
    EXPECT_EQ(Pose(back, 4)[e], identity[e]);
  }
  spine->GetFieldData()->GetArray("ImageToReference")->SetTuple(4, identity);
  ExpectIdentical(spine, back);
}

TEST(SequenceWriter, VtkMetaImageReaderSeesTheSamePixels)
{
  vtkSmartPointer<vtkImageData> spine = ReadSpine();
  const std::string file = OutputPath("for_metaio.mha");
  WriteThenRead(spine, file, true);
  vtkNew<vtkMetaImageReader> metaio;
  metaio->SetFileName(file.c_str());
  metaio->Update();
  vtkImageData* other = metaio->GetOutput();
  int dims[3];
  other->GetDimensions(dims);
  EXPECT_EQ(dims[0], 820);
  EXPECT_EQ(dims[1], 616);
  EXPECT_EQ(dims[2], 21);
  const double* spacing = other->GetSpacing();
  EXPECT_EQ(spacing[0], 1.0) << "ElementSpacing stays 1 1 1: the spacing lives in the matrices";
  EXPECT_EQ(std::memcmp(other->GetScalarPointer(), spine->GetScalarPointer(), std::size_t(820) * 616 * 21), 0);
}

TEST(SequenceWriter, FailedWriteLeavesTheExistingFileUntouched)
{
  const std::string file = OutputPath("keep_me.igs.mha");
  {
    std::ofstream out(file, std::ios::trunc);
    out << "precious";
  }
  vtkNew<vtkImageData> noPoses;
  noPoses->SetDimensions(4, 3, 2);
  noPoses->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  vtkNew<vtkUltrasoundSequenceWriter> writer;
  vtkNew<bigus_test::MessageCollector> errors;
  errors->Watch(writer);
  writer->SetInputData(noPoses);
  writer->SetFileName(file.c_str());
  writer->Write();
  EXPECT_NE(std::string(writer->GetLastErrorText()).find("ImageToReference"), std::string::npos);
  EXPECT_FALSE(errors->Errors.empty());
  EXPECT_EQ(bigus_test::ReadFileBytes(file), "precious");

  // An unwritable destination fails cleanly too.
  vtkNew<vtkDoubleArray> poses;
  poses->SetName("ImageToReference");
  poses->SetNumberOfComponents(16);
  const double identity[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
  poses->InsertNextTuple(identity);
  poses->InsertNextTuple(identity);
  noPoses->GetFieldData()->AddArray(poses);
  writer->SetFileName(OutputPath("no/such/folder/x.igs.mha").c_str());
  writer->Write();
  EXPECT_NE(std::string(writer->GetLastErrorText()).find("cannot write"), std::string::npos);
}

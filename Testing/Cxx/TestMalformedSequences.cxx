// vtkUltrasoundSequenceReader on the corpus of Testing/Data/Malformed (made by make_corpus.py from
// the nwire-phantom fixture; README.md there lists every file): every defective file must make the
// update fail, without a crash, with an ErrorEvent, an empty output and a message that names the
// file, the field and the frame; the well-formed variants (orientations, detached bodies, padding,
// CRLF, INVALID status, direct ImageToReference) must read back exactly what the fixture holds.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkSmartPointer.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <cctype>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <sstream>
#include <ostream>
#include <string>
#include <vector>

using bigus_test::DataPath;
using bigus_test::MessageCollector;
using bigus_test::OutputPath;
using bigus_test::Pose;

namespace
{
const char* const Fixture = "nwire-phantom/NwirePhantomFreehandCropped.igs.mha";
const char* const Calibration = "nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml";

std::string Corpus(const std::string& name)
{
  return DataPath("Malformed/" + name);
}

/// Result of one update of a fresh reader, with every VTK error message it produced.
struct ReadResult
{
  bool UpdateOk = false;
  std::string ErrorText;
  std::vector<std::string> Errors;
  std::vector<std::string> Warnings;
  std::string FileOrientation;
  std::string ChainInUse;
  vtkSmartPointer<vtkImageData> Output;
};

ReadResult Read(const std::string& path, bool calibration = true, int first = 0, int last = -1)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  vtkNew<MessageCollector> messages;
  messages->Watch(reader);
  messages->Watch(reader->GetExecutive()); // "Algorithm ... returned failure for request"
  reader->SetFileName(path.c_str());
  if (calibration)
  {
    reader->SetCalibrationFileName(DataPath(Calibration).c_str());
  }
  reader->SetFrameRange(first, last);
  ReadResult r;
  r.UpdateOk = reader->GetExecutive()->Update() != 0;
  r.ErrorText = reader->GetLastErrorText();
  r.Errors = messages->Errors;
  r.Warnings = messages->Warnings;
  r.FileOrientation = reader->GetFileOrientation();
  r.ChainInUse = reader->GetTransformChainInUse();
  r.Output = vtkSmartPointer<vtkImageData>::New();
  r.Output->DeepCopy(reader->GetOutput());
  return r;
}

/// Reads a file that must be accepted; fails the test (non-fatally) with the reader's message.
ReadResult ReadOk(const std::string& path, bool calibration = true, int first = 0, int last = -1)
{
  ReadResult r = Read(path, calibration, first, last);
  EXPECT_TRUE(r.UpdateOk) << path;
  EXPECT_EQ(r.ErrorText, "") << path;
  EXPECT_TRUE(r.Errors.empty()) << path << ": " << (r.Errors.empty() ? "" : r.Errors.front());
  return r;
}

std::string Bytes(vtkImageData* image)
{
  vtkDataArray* scalars = image->GetPointData()->GetScalars();
  if (!scalars)
  {
    return std::string();
  }
  const std::size_t n = static_cast<std::size_t>(scalars->GetNumberOfValues()) * scalars->GetDataTypeSize();
  return std::string(static_cast<const char*>(scalars->GetVoidPointer(0)), n);
}

double Field(vtkImageData* image, const char* name, int k)
{
  return image->GetFieldData()->GetArray(name)->GetTuple1(k);
}

/// Same pixels, dimensions, poses (within @p poseTolerance), timestamps, validity and frame numbers.
void ExpectSameSequence(vtkImageData* expected, vtkImageData* actual, double poseTolerance, const std::string& what)
{
  SCOPED_TRACE(what);
  int de[3], da[3];
  expected->GetDimensions(de);
  actual->GetDimensions(da);
  ASSERT_EQ(de[0], da[0]);
  ASSERT_EQ(de[1], da[1]);
  ASSERT_EQ(de[2], da[2]);
  ASSERT_NE(actual->GetPointData()->GetScalars(), nullptr);
  EXPECT_EQ(actual->GetScalarType(), expected->GetScalarType());
  EXPECT_TRUE(Bytes(expected) == Bytes(actual)) << "pixels differ";
  for (int k = 0; k < de[2]; ++k)
  {
    const auto pe = Pose(expected, k);
    const auto pa = Pose(actual, k);
    for (int c = 0; c < 16; ++c)
    {
      EXPECT_NEAR(pa[c], pe[c], poseTolerance) << "frame " << k << " entry " << c;
    }
    EXPECT_EQ(Field(actual, "Timestamp", k), Field(expected, "Timestamp", k)) << "frame " << k;
    EXPECT_EQ(Field(actual, "FrameValid", k), Field(expected, "FrameValid", k)) << "frame " << k;
    EXPECT_EQ(Field(actual, "FrameIndex", k), Field(expected, "FrameIndex", k)) << "frame " << k;
  }
}

// ------------------------------------------------------------------------------------------------
// Defective files: table-driven.
// ------------------------------------------------------------------------------------------------
struct MalformedCase
{
  const char* Name;                  ///< test name
  const char* File;                  ///< under Testing/Data/Malformed
  std::vector<std::string> Expected; ///< substrings the error text must contain (field, frame, ...)
  int First = 0;                     ///< FrameRange
  int Last = -1;
  bool Calibration = true; ///< SetCalibrationFileName(nwire XML) for ImageToProbe
};

void PrintTo(const MalformedCase& c, std::ostream* os)
{
  *os << c.File;
}

const std::vector<MalformedCase>& Cases()
{
  static const std::vector<MalformedCase> cases = {
    // Files and bodies.
    { "MissingFile", "does_not_exist.igs.mha", { "cannot open the sequence file" } },
    { "EmptyFile", "empty_file.igs.mha", { "no ElementDataFile field" } },
    { "TruncatedHeader", "truncated_header.igs.mha", { "ElementDataFile" } },
    { "TruncatedHeaderAtLine", "truncated_header_at_line.igs.mha",
      { "header has no ElementDataFile field (file ends after 41 lines)" } },
    { "TruncatedBody", "truncated_body.igs.mha",
      { "field CompressedDataSize says 4520 bytes but only 2260 follow", "truncated" } },
    { "TruncatedBodyNoSize", "truncated_body_no_size.igs.mha",
      { "truncated compressed body", "DimSize 200 x 150 x 4" } },
    { "CorruptBody", "corrupt_body.igs.mha",
      { "corrupt compressed body (zlib: invalid distance too far back) in frame 1" } },
    { "CorruptChecksum", "corrupt_checksum.igs.mha",
      { "corrupt compressed body (zlib: incorrect data check) in frame 3" } },
    { "CompressedSizeTooLarge", "compressed_size_too_large.igs.mha",
      { "field CompressedDataSize says 5520 bytes but only 4520 follow" } },
    { "DimSizeLargerCompressed", "dimsize_larger_compressed.igs.mha",
      { "compressed body holds 120000 bytes", "DimSize 200 x 151 x 4 needs 120800" } },
    { "DimSizeSmallerCompressed", "dimsize_smaller_compressed.igs.mha",
      { "compressed body holds more than the 119200 bytes", "DimSize 200 x 149 x 4" } },
    { "DimSizeLargerUncompressed", "dimsize_larger_uncompressed.mha",
      { "field DimSize 40 x 31 x 4 needs 4960 bytes", "holds 4800", "truncated" } },
    { "DimSizeSmallerUncompressed", "dimsize_smaller_uncompressed.mha",
      { "field DimSize 40 x 29 x 4 needs 4640 bytes", "holds 4800" } },
    { "MissingElementDataFileMha", "missing_elementdatafile.igs.mha", { "ElementDataFile" } },
    { "MissingElementDataFileMhd", "missing_elementdatafile.mhd", { "header has no ElementDataFile field" } },
    { "MissingRaw", "missing_raw.mhd",
      { "field ElementDataFile names 'missing_raw_does_not_exist.raw', which cannot be opened" } },
    { "ShortRaw", "short_raw.mhd",
      { "field DimSize 40 x 30 x 4 needs 4800 bytes", "short_raw.raw holds 4200", "truncated" } },
    // Header syntax and global fields.
    { "LineWithoutEquals", "line_without_equals.igs.mha",
      { "is not 'Key = Value': 'UltrasoundImageType BRIGHTNESS'" } },
    { "DuplicatedField", "duplicated_field.igs.mha", { "field DimSize appears twice" } },
    { "DuplicatedFrameField", "duplicated_frame_field.igs.mha",
      { "field Seq_Frame0001_ProbeToTrackerTransform appears twice" } },
    { "ElementTypeLongLong", "elementtype_long_long.igs.mha", { "field ElementType is 'MET_LONG_LONG'" } },
    { "ElementTypeGarbage", "elementtype_garbage.igs.mha", { "field ElementType is '???garbage'" } },
    { "MissingNDims", "missing_ndims.igs.mha", { "required field NDims is missing" } },
    { "NDims4", "ndims_4.igs.mha", { "field NDims is '4'" } },
    { "MissingDimSize", "missing_dimsize.igs.mha", { "required field DimSize is missing" } },
    { "DimSizeNotNumeric", "dimsize_not_numeric.igs.mha", { "field DimSize is '200 one-fifty 4'" } },
    { "OrientationFM", "orientation_fm.igs.mha", { "field UltrasoundImageOrientation is 'FM'" } },
    { "FrameBeyondDimSize", "frame_beyond_dimsize.igs.mha",
      { "frame 4: field Seq_Frame0004_", "beyond the 4 frames of DimSize" } },
    // Per-frame transforms and statuses.
    { "MissingTransformFrame2", "missing_transform_frame2.igs.mha",
      { "frame 2: field Seq_Frame0002_ProbeToTrackerTransform is missing" } },
    { "TransformNotNumericFrame1", "transform_not_numeric_frame1.igs.mha",
      { "frame 1: field Seq_Frame0001_ProbeToTrackerTransform is not 16 numbers" } },
    { "TransformCommaDecimalFrame3", "transform_comma_decimal_frame3.igs.mha",
      { "frame 3: field Seq_Frame0003_ProbeToTrackerTransform is not 16 numbers" } },
    { "Transform15NumbersFrame3", "transform_15_numbers_frame3.igs.mha",
      { "frame 3: field Seq_Frame0003_ProbeToTrackerTransform is not 16 numbers" } },
    { "Transform17NumbersFrame0", "transform_17_numbers_frame0.igs.mha",
      { "frame 0: field Seq_Frame0000_ReferenceToTrackerTransform is not 16 numbers" } },
    { "TransformNaNFrame3", "transform_nan_frame3.igs.mha",
      { "frame 3: field Seq_Frame0003_ProbeToTrackerTransform contains NaN or Inf" } },
    { "TransformInfFrame2", "transform_inf_frame2.igs.mha",
      { "frame 2: field Seq_Frame0002_ReferenceToTrackerTransform contains NaN or Inf" } },
    { "TransformOverflowFrame1", "transform_overflow_frame1.igs.mha",
      { "frame 1: field Seq_Frame0001_ProbeToTrackerTransform contains NaN or Inf" } },
    { "SingularProbeFrame2", "singular_probe_frame2.igs.mha",
      { "frame 2: ImageToReference = inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe is singular" } },
    { "SingularReferenceFrame1", "singular_reference_frame1.igs.mha",
      { "frame 1: field Seq_Frame0001_ReferenceToTrackerTransform is singular and cannot be inverted" } },
    { "ShearedFrame2", "sheared_imagetoreference_frame2.igs.mha",
      { "frame 2: ImageToReference = ImageToReference is sheared", "by 20" } },
    { "StatusMaybeFrame1", "status_maybe_frame1.igs.mha",
      { "frame 1: field Seq_Frame0001_ProbeToTrackerTransformStatus is 'MAYBE', expected OK or INVALID" } },
    { "ImageStatusMaybeFrame2", "imagestatus_maybe_frame2.igs.mha",
      { "frame 2:", "Seq_Frame0002_ImageStatus", "MAYBE" } },
    // A valid file read the wrong way.
    { "NoCalibration", "valid_4frames.igs.mha",
      { "transform ImageToProbe of chain 'inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe' not found",
        "no CalibrationFileName" },
      0, -1, false },
    { "FrameRangePastEnd", "valid_4frames.igs.mha", { "FrameRange 2 9 is outside the 4 frames of the file" }, 2, 9 },
    { "FrameRangeReversed", "valid_4frames.igs.mha", { "FrameRange 3 1 is outside the 4 frames" }, 3, 1 },
    { "FrameRangeNegative", "valid_4frames.igs.mha", { "FrameRange -1 2 is outside the 4 frames" }, -1, 2 },
    { "FrameRangeFirstPastEnd", "valid_4frames.igs.mha", { "FrameRange 4 -1 is outside the 4 frames" }, 4, -1 },
  };
  return cases;
}

class MalformedSequence : public ::testing::TestWithParam<MalformedCase>
{};

TEST_P(MalformedSequence, FailsWithPreciseMessage)
{
  const MalformedCase& c = GetParam();
  const std::string path = Corpus(c.File);
  const ReadResult r = Read(path, c.Calibration, c.First, c.Last);

  EXPECT_FALSE(r.UpdateOk) << path << " was accepted";
  ASSERT_FALSE(r.ErrorText.empty()) << path << " was accepted without an error text";
  EXPECT_NE(r.ErrorText.find(path), std::string::npos) << "message does not name the file: " << r.ErrorText;
  for (const std::string& expected : c.Expected)
  {
    EXPECT_NE(r.ErrorText.find(expected), std::string::npos)
      << "message lacks \"" << expected << "\"\n  message: " << r.ErrorText;
  }
  // The error went through vtkErrorMacro (ErrorEvent on the reader) with the same text.
  bool reported = false;
  for (const std::string& e : r.Errors)
  {
    reported = reported || e.find(r.ErrorText) != std::string::npos;
  }
  EXPECT_TRUE(reported) << "no ErrorEvent carried the message (" << r.Errors.size() << " error events)";
  // Nothing is guessed: no pixels, no poses.
  EXPECT_EQ(r.Output->GetNumberOfPoints(), 0);
  EXPECT_EQ(r.Output->GetPointData()->GetScalars(), nullptr);
  EXPECT_EQ(r.Output->GetFieldData()->GetArray("ImageToReference"), nullptr);
}

INSTANTIATE_TEST_SUITE_P(Corpus, MalformedSequence, ::testing::ValuesIn(Cases()),
  [](const ::testing::TestParamInfo<MalformedCase>& info) { return std::string(info.param.Name); });

// ------------------------------------------------------------------------------------------------
// Well-formed variants of the fixture.
// ------------------------------------------------------------------------------------------------
class WellFormedSequence : public ::testing::Test
{
protected:
  static void SetUpTestSuite()
  {
    FirstFour = ReadOk(DataPath(Fixture), true, 0, 3).Output;
    All = ReadOk(DataPath(Fixture)).Output;
  }
  static void TearDownTestSuite()
  {
    FirstFour = nullptr;
    All = nullptr;
  }
  static vtkSmartPointer<vtkImageData> FirstFour; ///< frames 0-3 of the fixture
  static vtkSmartPointer<vtkImageData> All;       ///< the 20 frames of the fixture
};
vtkSmartPointer<vtkImageData> WellFormedSequence::FirstFour;
vtkSmartPointer<vtkImageData> WellFormedSequence::All;

TEST_F(WellFormedSequence, FixtureSanity)
{
  int dims[3];
  All->GetDimensions(dims);
  EXPECT_EQ(dims[0], 200);
  EXPECT_EQ(dims[1], 150);
  EXPECT_EQ(dims[2], 20);
  FirstFour->GetDimensions(dims);
  ASSERT_EQ(dims[2], 4);
  for (int k = 0; k < 4; ++k)
  {
    EXPECT_EQ(Field(FirstFour, "FrameValid", k), 1);
  }
  // The flip tests below are only meaningful if frames are neither left-right nor up-down symmetric.
  const std::string b = Bytes(FirstFour);
  bool lrAsymmetric = false, udAsymmetric = false;
  for (int j = 0; j < dims[1]; ++j)
  {
    for (int i = 0; i < dims[0]; ++i)
    {
      lrAsymmetric = lrAsymmetric || b[j * dims[0] + i] != b[j * dims[0] + dims[0] - 1 - i];
      udAsymmetric = udAsymmetric || b[j * dims[0] + i] != b[(dims[1] - 1 - j) * dims[0] + i];
    }
  }
  EXPECT_TRUE(lrAsymmetric);
  EXPECT_TRUE(udAsymmetric);
}

TEST_F(WellFormedSequence, FourFrameCopyMatchesFixture)
{
  const ReadResult r = ReadOk(Corpus("valid_4frames.igs.mha"));
  ASSERT_TRUE(r.UpdateOk);
  ExpectSameSequence(FirstFour, r.Output, 0.0, "valid_4frames.igs.mha");
}

TEST_F(WellFormedSequence, OrientationsAreFlippedBackToMF)
{
  for (const char* code : { "UF", "MN", "UN" })
  {
    std::string file =
      std::string("orientation_") + char(std::tolower(code[0])) + char(std::tolower(code[1])) + ".igs.mha";
    const ReadResult r = ReadOk(Corpus(file));
    ASSERT_TRUE(r.UpdateOk) << file;
    EXPECT_EQ(r.FileOrientation, code) << file;
    ExpectSameSequence(FirstFour, r.Output, 0.0, file);
  }
}

TEST_F(WellFormedSequence, InvalidTransformStatusMarksOnlyThatFrame)
{
  const ReadResult r = ReadOk(Corpus("invalid_status_frame1.igs.mha"));
  ASSERT_TRUE(r.UpdateOk);
  ASSERT_NE(r.Output->GetFieldData()->GetArray("FrameValid"), nullptr);
  EXPECT_EQ(Field(r.Output, "FrameValid", 0), 1);
  EXPECT_EQ(Field(r.Output, "FrameValid", 1), 0);
  EXPECT_EQ(Field(r.Output, "FrameValid", 2), 1);
  EXPECT_EQ(Field(r.Output, "FrameValid", 3), 1);
  EXPECT_TRUE(Bytes(FirstFour) == Bytes(r.Output));
  for (int k : { 0, 2, 3 })
  {
    EXPECT_EQ(Pose(r.Output, k), Pose(FirstFour, k)) << "frame " << k;
  }
}

TEST_F(WellFormedSequence, DetachedBodiesMatchFixture)
{
  const ReadResult raw = ReadOk(Corpus("copy_uncompressed.mhd"));
  ASSERT_TRUE(raw.UpdateOk);
  ExpectSameSequence(FirstFour, raw.Output, 0.0, "copy_uncompressed.mhd + .raw");

  const ReadResult zraw = ReadOk(Corpus("copy_compressed.mhd"));
  ASSERT_TRUE(zraw.UpdateOk);
  ExpectSameSequence(All, zraw.Output, 0.0, "copy_compressed.mhd + .zraw");

  // Frame range on a detached uncompressed body (seeks into the .raw).
  const ReadResult part = ReadOk(Corpus("copy_uncompressed.mhd"), true, 2, 3);
  ASSERT_TRUE(part.UpdateOk);
  const ReadResult fixturePart = ReadOk(DataPath(Fixture), true, 2, 3);
  ExpectSameSequence(fixturePart.Output, part.Output, 0.0, "copy_uncompressed.mhd frames 2-3");
}

TEST_F(WellFormedSequence, PaddingAndCrlfAreIgnored)
{
  const ReadResult padded = ReadOk(Corpus("padded_values.igs.mha"));
  ASSERT_TRUE(padded.UpdateOk);
  ExpectSameSequence(FirstFour, padded.Output, 0.0, "padded_values.igs.mha");

  const ReadResult crlf = ReadOk(Corpus("crlf.igs.mha"));
  ASSERT_TRUE(crlf.UpdateOk);
  ExpectSameSequence(FirstFour, crlf.Output, 0.0, "crlf.igs.mha");

  const ReadResult crlfMhd = ReadOk(Corpus("crlf_compressed.mhd"));
  ASSERT_TRUE(crlfMhd.UpdateOk);
  ExpectSameSequence(All, crlfMhd.Output, 0.0, "crlf_compressed.mhd");
}

TEST_F(WellFormedSequence, DirectImageToReferenceMatchesChain)
{
  // No calibration file: the per-frame ImageToReferenceTransform needs no ImageToProbe.
  const ReadResult r = ReadOk(Corpus("imagetoreference_direct.igs.mha"), false);
  ASSERT_TRUE(r.UpdateOk);
  EXPECT_EQ(r.ChainInUse, "ImageToReference");
  ExpectSameSequence(FirstFour, r.Output, 1e-9, "imagetoreference_direct.igs.mha");
}

// Files that are not what a header says, written here from copy_uncompressed.mhd (issue 56): a DimSize of
// 16384 x 16384 x 256 (64 GiB; frame fields copied for 256 frames) over its 120 KB of pixels is refused by the sizes
// before anything is allocated (it was allocated first: std::bad_alloc, or ASan's allocation-size abort); a
// sequence or an ElementDataFile that is a pipe or a folder is refused at once (a pipe blocked the reader forever).
TEST(MalformedSequenceSizes, WhatTheFileCannotHoldOrIsNotAFileIsRefusedBeforeReading)
{
  std::ifstream in(Corpus("copy_uncompressed.mhd"), std::ios::binary);
  std::string header((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto withLine = [&](const std::string& key, const std::string& value) {
    std::string text = header;
    const std::size_t at = text.find(key + " = ");
    text.replace(at, text.find('\n', at) - at, key + " = " + value);
    return text;
  };
  const std::string raw = Corpus("copy_uncompressed.raw");
  auto write = [](const std::string& path, const std::string& text) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
    return path;
  };
  header = withLine("ElementDataFile", raw);
  std::string frames; // frame 0's fields again for frames 4 to 255, before the ElementDataFile line
  std::istringstream lines(header);
  for (std::string line; std::getline(lines, line);)
  {
    for (int k = 4; k < 256 && line.rfind("Seq_Frame0000_", 0) == 0; ++k)
    {
      char name[16];
      std::snprintf(name, sizeof(name), "Seq_Frame%04d", k);
      frames += name + line.substr(13) + "\n";
    }
  }
  std::string many = withLine("DimSize", "16384 16384 256");
  many.insert(many.find("ElementDataFile = "), frames);
  ReadResult r = Read(write(OutputPath("dimsize_huge.mhd"), many));
  EXPECT_FALSE(r.UpdateOk);
  EXPECT_NE(
    r.ErrorText.find("DimSize 16384 x 16384 x 256 needs 68719476736 bytes of pixel data but"), std::string::npos)
    << r.ErrorText;
  EXPECT_EQ(r.Output->GetNumberOfPoints(), 0);

  const std::string pipe = OutputPath("sequence_pipe.igs.mha");
  std::remove(pipe.c_str());
  ASSERT_EQ(::mkfifo(pipe.c_str(), 0600), 0);
  r = Read(pipe);
  EXPECT_FALSE(r.UpdateOk);
  EXPECT_NE(r.ErrorText.find("not a regular file"), std::string::npos) << r.ErrorText;
  for (const std::string& data : { pipe, OutputPath("") })
  {
    r = Read(write(OutputPath("data_not_a_file.mhd"), withLine("ElementDataFile", data)));
    EXPECT_FALSE(r.UpdateOk);
    EXPECT_NE(r.ErrorText.find("which is not a regular file"), std::string::npos) << r.ErrorText;
  }
  std::remove(pipe.c_str());
}

TEST(MalformedSequenceReuse, ErrorIsClearedByTheNextGoodFile)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  vtkNew<MessageCollector> messages;
  messages->Watch(reader);
  messages->Watch(reader->GetExecutive());
  reader->SetCalibrationFileName(DataPath(Calibration).c_str());
  reader->SetFileName(Corpus("transform_nan_frame3.igs.mha").c_str());
  EXPECT_EQ(reader->GetExecutive()->Update(), 0);
  EXPECT_NE(std::string(reader->GetLastErrorText()), "");
  EXPECT_EQ(reader->GetOutput()->GetNumberOfPoints(), 0);
  EXPECT_FALSE(messages->Errors.empty());

  messages->Errors.clear();
  reader->SetFileName(Corpus("valid_4frames.igs.mha").c_str());
  EXPECT_NE(reader->GetExecutive()->Update(), 0);
  EXPECT_STREQ(reader->GetLastErrorText(), "");
  EXPECT_EQ(reader->GetOutput()->GetNumberOfPoints(), 200 * 150 * 4);
  EXPECT_TRUE(messages->Errors.empty());

  // And back to a bad file: the previous good output must not survive.
  reader->SetFileName(Corpus("dimsize_larger_compressed.igs.mha").c_str());
  EXPECT_EQ(reader->GetExecutive()->Update(), 0);
  EXPECT_NE(std::string(reader->GetLastErrorText()).find("DimSize 200 x 151 x 4"), std::string::npos);
  EXPECT_EQ(reader->GetOutput()->GetNumberOfPoints(), 0);
}
} // namespace

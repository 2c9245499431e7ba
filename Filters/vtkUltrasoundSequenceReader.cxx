#include "vtkUltrasoundSequenceReader.h"

#include "bigusMetaImageHeader.h"
#include "bigusRenderer.h"
#include "bigusSliceFrame.h"
#include "vtkUltrasoundCalibration.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkIntArray.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkUnsignedCharArray.h"

#include <sys/stat.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <vector>

namespace
{
using Matrix = std::array<double, 16>;
constexpr Matrix Identity = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };

std::string DirectoryOf(const std::string& path)
{
  const std::size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
}

/**
 * Whether the row-major 4x4 @p m is rigid: its 3x3 part R has R^T R = I within 1e-2 (scale within about 1 %), its
 * last row is 0 0 0 1 and its translation lies within 1e7 mm; otherwise @p why says what is wrong. A singular R
 * passes here: the chain's inversion and slice-frame checks report it.
 */
bool IsRigid(const double m[16], std::string& why)
{
  double largest = 0;
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      const double dot = m[i] * m[j] + m[4 + i] * m[4 + j] + m[8 + i] * m[8 + j];
      largest = std::max(largest, std::abs(dot - (i == j ? 1.0 : 0.0)));
    }
  }
  const double shift = std::sqrt(m[3] * m[3] + m[7] * m[7] + m[11] * m[11]);
  // A singular 3x3 part (relative to its columns' lengths) is left to the chain's own checks, which name it so.
  const double det =
    m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) + m[2] * (m[4] * m[9] - m[5] * m[8]);
  double columns = 1;
  for (int j = 0; j < 3; ++j)
  {
    columns *= std::sqrt(m[j] * m[j] + m[4 + j] * m[4 + j] + m[8 + j] * m[8 + j]);
  }
  std::ostringstream text;
  if (!(std::abs(det) > 1e-9 * columns))
  {
    return true;
  }
  if (m[12] != 0 || m[13] != 0 || m[14] != 0 || m[15] != 1)
  {
    text << "its last row is not 0 0 0 1";
  }
  else if (!(largest <= 1e-2))
  {
    text << "its 3x3 part is not a rotation: R^T R differs from the identity by " << largest;
  }
  else if (det < 0)
  {
    text << "its 3x3 part is a reflection (determinant " << det << ")";
  }
  else if (!(shift <= 1e7))
  {
    text << "its translation is " << shift << " mm";
  }
  why = text.str();
  return why.empty();
}

std::string JoinNames(const std::set<std::string>& names)
{
  std::string out;
  for (const auto& n : names)
  {
    out += (out.empty() ? "" : ", ") + n;
  }
  return out.empty() ? "(none)" : out;
}
}

class vtkUltrasoundSequenceReader::vtkInternals
{
public:
  bigus::MetaImageHeader Header;
  bigus::MetaImageLayout Layout;
  std::string ChainInUse;
  std::string LastError;
  std::map<std::string, Matrix> StaticTransforms;
  int First = 0; // first frame read, file numbering
  int Count = 0; // frames read
  std::vector<Matrix> Poses;
  std::vector<unsigned char> Valid;
  std::vector<double> Timestamps;

  /// Per-frame transform names present in any frame (e.g. "ProbeToTrackerTransform").
  std::set<std::string> FrameTransformNames() const
  {
    std::set<std::string> names;
    for (const auto& frame : this->Header.FrameFields)
    {
      for (const auto& field : frame.second)
      {
        const std::string& name = field.first;
        if (name.size() > 9 && name.compare(name.size() - 9, 9, "Transform") == 0)
        {
          names.insert(name);
        }
      }
    }
    return names;
  }

  const std::string* FrameField(int frame, const std::string& field) const
  {
    auto f = this->Header.FrameFields.find(frame);
    if (f == this->Header.FrameFields.end())
    {
      return nullptr;
    }
    auto it = f->second.find(field);
    return it == f->second.end() ? nullptr : &it->second;
  }
};

vtkStandardNewMacro(vtkUltrasoundSequenceReader);

vtkUltrasoundSequenceReader::vtkUltrasoundSequenceReader()
  : Internals(new vtkInternals)
{
  this->MaximumShearAngle = bigus::DefaultMaximumShearAngle;
  this->SetNumberOfInputPorts(0);
}

vtkUltrasoundSequenceReader::~vtkUltrasoundSequenceReader()
{
  this->SetFileName(nullptr);
  this->SetTransformChain(nullptr);
  this->SetCalibrationFileName(nullptr);
}

void vtkUltrasoundSequenceReader::SetStaticTransform(const char* name, vtkMatrix4x4* matrix)
{
  if (!name || !*name || !matrix)
  {
    vtkErrorMacro("SetStaticTransform needs a name and a matrix");
    return;
  }
  std::string key = name;
  if (key.size() > 9 && key.compare(key.size() - 9, 9, "Transform") == 0)
  {
    key.resize(key.size() - 9);
  }
  Matrix m;
  std::copy(matrix->GetData(), matrix->GetData() + 16, m.begin());
  this->Internals->StaticTransforms[key] = m;
  this->Modified();
}

void vtkUltrasoundSequenceReader::RemoveAllStaticTransforms()
{
  if (!this->Internals->StaticTransforms.empty())
  {
    this->Internals->StaticTransforms.clear();
    this->Modified();
  }
}

const char* vtkUltrasoundSequenceReader::GetTransformChainInUse() const
{
  return this->Internals->ChainInUse.c_str();
}

const char* vtkUltrasoundSequenceReader::GetFileOrientation() const
{
  return this->Internals->Layout.Orientation.c_str();
}

const char* vtkUltrasoundSequenceReader::GetLastErrorText() const
{
  return this->Internals->LastError.c_str();
}

int vtkUltrasoundSequenceReader::Fail(const std::string& message)
{
  this->Internals->LastError = message;
  vtkErrorMacro(<< message);
  return 0;
}

namespace
{
/// zlib's largest ratio of inflated to deflated bytes (its technical details: 1032:1 at most).
constexpr std::uint64_t MaximumInflation = 1032;

/// Whether @p path names a regular file (not a folder, a pipe, a device); false when it does not exist.
bool IsRegularFile(const std::string& path)
{
  struct stat s;
  return ::stat(path.c_str(), &s) == 0 && S_ISREG(s.st_mode);
}

/// Whether anything (a file, a folder, a pipe ...) is at @p path.
bool Exists(const std::string& path)
{
  struct stat s;
  return ::stat(path.c_str(), &s) == 0;
}
}

int vtkUltrasoundSequenceReader::RequestInformation(
  vtkInformation*, vtkInformationVector**, vtkInformationVector* outputVector)
{
  vtkInternals& in = *this->Internals;
  in.LastError.clear();
  in.ChainInUse.clear();
  in.Poses.clear();
  in.Valid.clear();
  in.Timestamps.clear();
  in.Count = 0;
  this->NumberOfFramesInFile = 0;
  if (!this->FileName || !*this->FileName)
  {
    return this->Fail("vtkUltrasoundSequenceReader: no FileName set");
  }
  const std::string file = this->FileName;
  if (Exists(file) && !IsRegularFile(file))
  {
    return this->Fail(file + ": not a regular file (a folder, a pipe or a device cannot be read as a sequence)");
  }
  try
  {
    std::ifstream stream(file, std::ios::binary);
    if (!stream)
    {
      return this->Fail(file + ": cannot open the sequence file (missing or unreadable)");
    }
    in.Header = bigus::ParseMetaImageHeader(stream, file);
    in.Layout = bigus::InterpretMetaImageHeader(in.Header, file);
  }
  catch (const bigus::MetaImageError& e)
  {
    return this->Fail(e.what());
  }
  const bigus::MetaImageLayout& layout = in.Layout;
  const int frames = layout.Dimensions[2];
  this->NumberOfFramesInFile = frames;
  const int first = this->FrameRange[0];
  const int last = this->FrameRange[1] < 0 ? frames - 1 : this->FrameRange[1];
  if (first < 0 || first > last || last >= frames)
  {
    return this->Fail(file + ": FrameRange " + std::to_string(this->FrameRange[0]) + " " +
      std::to_string(this->FrameRange[1]) + " is outside the " + std::to_string(frames) + " frames of the file");
  }
  in.First = first;
  in.Count = last - first + 1;

  vtkNew<vtkUltrasoundCalibration> calibration;
  if (this->CalibrationFileName && *this->CalibrationFileName)
  {
    calibration->SetFileName(this->CalibrationFileName);
    if (!calibration->Parse())
    {
      return this->Fail(calibration->GetErrorText());
    }
  }

  // Resolve the chain.
  const std::set<std::string> perFrame = in.FrameTransformNames();
  std::string chain = this->TransformChain ? this->TransformChain : "";
  if (chain.empty())
  {
    if (perFrame.count("ImageToReferenceTransform"))
    {
      chain = "ImageToReference";
    }
    else if (perFrame.count("ProbeToTrackerTransform") && perFrame.count("ReferenceToTrackerTransform"))
    {
      chain = "inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe";
    }
    else
    {
      return this->Fail(file +
        ": cannot choose ImageToReference automatically (no per-frame "
        "ImageToReferenceTransform, nor ProbeToTracker and ReferenceToTracker); "
        "set TransformChain. Per-frame transforms in the file: " +
        JoinNames(perFrame));
    }
  }
  std::vector<bigus::TransformTerm> terms;
  try
  {
    terms = bigus::ParseTransformChain(chain);
  }
  catch (const bigus::MetaImageError& e)
  {
    return this->Fail(file + ": " + e.what());
  }

  // Static factors are resolved once; per-frame ones for every frame.
  std::vector<Matrix> staticMatrix(terms.size());
  std::vector<bool> isPerFrame(terms.size());
  for (std::size_t t = 0; t < terms.size(); ++t)
  {
    const std::string field = terms[t].Name + "Transform";
    isPerFrame[t] = perFrame.count(field) > 0;
    if (isPerFrame[t])
    {
      continue;
    }
    Matrix& m = staticMatrix[t];
    vtkNew<vtkMatrix4x4> fromXml;
    auto user = in.StaticTransforms.find(terms[t].Name);
    auto header = in.Header.Fields.find(field);
    if (user != in.StaticTransforms.end())
    {
      m = user->second;
    }
    else if (calibration->GetTransform(terms[t].Name.c_str(), fromXml))
    {
      std::copy(fromXml->GetData(), fromXml->GetData() + 16, m.begin());
    }
    else if (header != in.Header.Fields.end())
    {
      if (!bigus::ParseNumbers(header->second, m.data(), 16))
      {
        return this->Fail(file + ": field " + field + " is not 16 numbers (row-major 4x4)");
      }
    }
    else
    {
      return this->Fail(file + ": transform " + terms[t].Name + " of chain '" + chain +
        "' not found: no per-frame field " + bigus::FrameFieldName(first, field) +
        ", no static transform of that name, " +
        (calibration->GetFileName() ? "not in " + std::string(calibration->GetFileName())
                                    : std::string("no CalibrationFileName")) +
        ", no header field " + field + ". Per-frame transforms in the file: " + JoinNames(perFrame));
    }
    for (double v : m)
    {
      if (!std::isfinite(v))
      {
        return this->Fail(file + ": static transform " + terms[t].Name + " contains NaN or Inf");
      }
    }
    if (terms[t].Inverse && !bigus::InvertAffine4x4(m.data(), m.data()))
    {
      return this->Fail(file + ": static transform " + terms[t].Name + " is singular and cannot be inverted");
    }
  }

  in.Poses.assign(in.Count, Identity);
  in.Valid.assign(in.Count, 1);
  in.Timestamps.assign(in.Count, 0.0);
  for (int k = first; k <= last; ++k)
  {
    const int out = k - first;
    bool valid = true;
    Matrix pose = Identity;
    if (const std::string* status = in.FrameField(k, "ImageStatus"))
    {
      if (*status != "OK" && *status != "INVALID")
      {
        return this->Fail(file + ": frame " + std::to_string(k) + ": field " + bigus::FrameFieldName(k, "ImageStatus") +
          " is '" + status->substr(0, 40) + "', expected OK or INVALID");
      }
      valid = *status == "OK";
    }
    for (std::size_t t = 0; t < terms.size(); ++t)
    {
      Matrix m = staticMatrix[t];
      if (isPerFrame[t])
      {
        const std::string field = terms[t].Name + "Transform";
        const std::string name = bigus::FrameFieldName(k, field);
        const std::string* value = in.FrameField(k, field);
        if (!value)
        {
          return this->Fail(file + ": frame " + std::to_string(k) + ": field " + name + " is missing");
        }
        if (!bigus::ParseNumbers(*value, m.data(), 16))
        {
          return this->Fail(
            file + ": frame " + std::to_string(k) + ": field " + name + " is not 16 numbers (row-major 4x4)");
        }
        bool transformValid = true;
        if (const std::string* status = in.FrameField(k, field + "Status"))
        {
          if (*status == "INVALID")
          {
            transformValid = false;
          }
          else if (*status != "OK")
          {
            return this->Fail(file + ": frame " + std::to_string(k) + ": field " + name + "Status is '" +
              status->substr(0, 40) + "', expected OK or INVALID");
          }
        }
        if (!transformValid)
        {
          valid = false;
          continue; // the stored matrix of an INVALID transform is not used
        }
        for (double v : m)
        {
          if (!std::isfinite(v))
          {
            return this->Fail(file + ": frame " + std::to_string(k) + ": field " + name + " contains NaN or Inf");
          }
        }
        if (terms[t].Name.rfind("Image", 0) != 0)
        {
          // A tracker's transform (a tool or the reference to the tracker) is a rotation and a translation: one
          // that scales, shears or lies beyond 1e7 mm would train a field of another size or far away.
          std::string why;
          if (!IsRigid(m.data(), why))
          {
            return this->Fail(file + ": frame " + std::to_string(k) + ": field " + name + " is not rigid (" + why +
              "); a tracker's transform is a rotation and a translation");
          }
        }
        if (terms[t].Inverse && !bigus::InvertAffine4x4(m.data(), m.data()))
        {
          return this->Fail(
            file + ": frame " + std::to_string(k) + ": field " + name + " is singular and cannot be inverted");
        }
      }
      bigus::MultiplyMatrix4x4(pose.data(), m.data(), pose.data());
    }
    if (valid)
    {
      bigus::SliceFrame frame;
      const bigus::PoseStatus status = bigus::ComputeSliceFrame(pose.data(), this->MaximumShearAngle, frame);
      if (status != bigus::PoseStatus::Ok)
      {
        std::ostringstream why;
        why << file << ": frame " << k << ": ImageToReference = " << chain << " " << bigus::PoseStatusText(status);
        if (status == bigus::PoseStatus::Sheared)
        {
          why << " by " << frame.shearDegrees << " degrees (MaximumShearAngle " << this->MaximumShearAngle << ")";
        }
        return this->Fail(why.str());
      }
      in.Poses[out] = pose;
    }
    in.Valid[out] = valid ? 1 : 0;
    if (const std::string* stamp = in.FrameField(k, "Timestamp"))
    {
      if (!bigus::ParseNumbers(*stamp, &in.Timestamps[out], 1) || !std::isfinite(in.Timestamps[out]))
      {
        return this->Fail(file + ": frame " + std::to_string(k) + ": field " + bigus::FrameFieldName(k, "Timestamp") +
          " is not a finite number");
      }
    }
    else
    {
      return this->Fail(
        file + ": frame " + std::to_string(k) + ": field " + bigus::FrameFieldName(k, "Timestamp") + " is missing");
    }
  }
  in.ChainInUse = chain;

  const int extent[6] = { 0, layout.Dimensions[0] - 1, 0, layout.Dimensions[1] - 1, 0, in.Count - 1 };
  vtkInformation* info = outputVector->GetInformationObject(0);
  info->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  const double spacing[3] = { 1, 1, 1 };
  const double origin[3] = { 0, 0, 0 };
  info->Set(vtkDataObject::SPACING(), spacing, 3);
  info->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(
    info, layout.ElementType == bigus::MetaElementType::UChar ? VTK_UNSIGNED_CHAR : VTK_FLOAT, 1);
  return 1;
}

int vtkUltrasoundSequenceReader::RequestData(
  vtkInformation*, vtkInformationVector**, vtkInformationVector* outputVector)
{
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  output->Initialize();
  // Every failure leaves an empty output: no partly filled sweep reaches the pipeline.
  auto fail = [&](const std::string& message) {
    output->Initialize();
    return this->Fail(message);
  };
  vtkInternals& in = *this->Internals;
  if (in.Count == 0)
  {
    return 0; // RequestInformation failed and reported why
  }
  const std::string file = this->FileName;
  const bigus::MetaImageLayout& layout = in.Layout;
  const int width = layout.Dimensions[0];
  const int height = layout.Dimensions[1];
  const int frames = layout.Dimensions[2];
  const std::uint64_t frameBytes = layout.FrameBytes();
  const std::uint64_t expected = frameBytes * std::uint64_t(frames);

  std::string dataPath = file;
  std::uint64_t offset = in.Header.DataOffset;
  if (layout.ElementDataFile != "LOCAL")
  {
    dataPath = layout.ElementDataFile[0] == '/' ? layout.ElementDataFile : DirectoryOf(file) + layout.ElementDataFile;
    offset = 0;
  }
  if (Exists(dataPath) && !IsRegularFile(dataPath))
  {
    return fail(file + ": field ElementDataFile names '" + layout.ElementDataFile + "' (" + dataPath +
      "), which is not a regular file (a folder, a pipe or a device)");
  }
  std::ifstream data(dataPath, std::ios::binary | std::ios::ate);
  if (!data)
  {
    return fail(file + ": field ElementDataFile names '" + layout.ElementDataFile + "', which cannot be opened (" +
      dataPath + ")");
  }
  const std::uint64_t fileSize = static_cast<std::uint64_t>(data.tellg());
  const std::uint64_t available = fileSize > offset ? fileSize - offset : 0;
  data.seekg(static_cast<std::streamoff>(offset));
  // The sizes before any allocation: a DimSize the data cannot hold is refused here, not after allocating it.
  const std::string dims = std::to_string(width) + " x " + std::to_string(height) + " x " + std::to_string(frames);
  if (!layout.Compressed && available != expected)
  {
    return fail(file + ": field DimSize " + dims + " needs " + std::to_string(expected) + " bytes of pixel data but " +
      dataPath + " holds " + std::to_string(available) + (available < expected ? " (truncated file?)" : ""));
  }
  if (layout.Compressed && expected / MaximumInflation > available)
  {
    return fail(file + ": field DimSize " + dims + " needs " + std::to_string(expected) +
      " bytes of pixel data but the compressed body in " + dataPath + " holds " + std::to_string(available) +
      " bytes, which inflate to at most " + std::to_string(available * MaximumInflation) + " (truncated file?)");
  }

  output->SetExtent(0, width - 1, 0, height - 1, 0, in.Count - 1);
  output->SetSpacing(1, 1, 1);
  output->SetOrigin(0, 0, 0);
  vtkSmartPointer<vtkDataArray> scalars;
  if (layout.ElementType == bigus::MetaElementType::UChar)
  {
    scalars = vtkSmartPointer<vtkUnsignedCharArray>::New();
  }
  else
  {
    scalars = vtkSmartPointer<vtkFloatArray>::New();
  }
  scalars->SetName("Intensity");
  scalars->SetNumberOfComponents(1);
  const vtkIdType tuples = vtkIdType(width) * height * in.Count;
  const bool allocated = scalars->Allocate(tuples) != 0;
  if (allocated)
  {
    scalars->SetNumberOfTuples(tuples);
  }
  if (!allocated || scalars->GetNumberOfTuples() != tuples)
  {
    return fail(file + ": cannot allocate the " + std::to_string(frameBytes * std::uint64_t(in.Count)) +
      " bytes that frames " + std::to_string(in.First) + " to " + std::to_string(in.First + in.Count - 1) +
      " need (field DimSize " + dims + ")");
  }
  unsigned char* dst = static_cast<unsigned char*>(scalars->GetVoidPointer(0));

  const bool flipColumns = layout.Orientation[0] == 'U';
  const bool flipRows = layout.Orientation[1] == 'N';
  const std::size_t bpp = layout.BytesPerPixel();
  std::vector<unsigned char> frame(frameBytes);
  // Copies file frame k (in `frame`) into the output in MF orientation, little-endian.
  auto store = [&](int k) {
    if (k < in.First || k >= in.First + in.Count)
    {
      return;
    }
    if (layout.ByteOrderMSB && bpp > 1)
    {
      for (std::size_t p = 0; p < frame.size(); p += bpp)
      {
        std::reverse(frame.begin() + p, frame.begin() + p + bpp);
      }
    }
    unsigned char* out = dst + std::uint64_t(k - in.First) * frameBytes;
    for (int j = 0; j < height; ++j)
    {
      const unsigned char* src = frame.data() + std::uint64_t(flipRows ? height - 1 - j : j) * width * bpp;
      unsigned char* row = out + std::uint64_t(j) * width * bpp;
      if (!flipColumns)
      {
        std::memcpy(row, src, width * bpp);
        continue;
      }
      for (int i = 0; i < width; ++i)
      {
        std::memcpy(row + std::size_t(i) * bpp, src + std::size_t(width - 1 - i) * bpp, bpp);
      }
    }
  };
  if (!layout.Compressed)
  {
    data.seekg(static_cast<std::streamoff>(offset + std::uint64_t(in.First) * frameBytes));
    for (int k = in.First; k < in.First + in.Count; ++k)
    {
      if (!data.read(reinterpret_cast<char*>(frame.data()), frameBytes))
      {
        return fail(file + ": frame " + std::to_string(k) + ": read error in " + dataPath);
      }
      store(k);
      this->UpdateProgress(double(k - in.First + 1) / in.Count);
      if (this->AbortExecute)
      {
        output->Initialize();
        return 0;
      }
    }
  }
  else
  {
    std::uint64_t body = available;
    if (layout.CompressedDataSize >= 0)
    {
      if (std::uint64_t(layout.CompressedDataSize) > available)
      {
        return fail(file + ": field CompressedDataSize says " + std::to_string(layout.CompressedDataSize) +
          " bytes but only " + std::to_string(available) + " follow in " + dataPath + " (truncated file?)");
      }
      body = std::uint64_t(layout.CompressedDataSize);
    }
    z_stream z;
    std::memset(&z, 0, sizeof(z));
    if (inflateInit2(&z, 15 + 32) != Z_OK) // zlib or gzip wrapper, detected from the stream
    {
      return fail(file + ": cannot initialise zlib");
    }
    std::vector<unsigned char> chunk(1 << 20);
    std::uint64_t consumed = 0;
    int status = Z_OK;
    int k = 0;            // frame being inflated
    bool probing = false; // all frames done: any further byte is surplus
    unsigned char spare = 0;
    std::string error;
    z.next_out = frame.data();
    z.avail_out = static_cast<uInt>(frameBytes);
    auto inflatedSoFar = [&]() { return std::uint64_t(k) * frameBytes + (frameBytes - z.avail_out); };
    while (status != Z_STREAM_END)
    {
      if (z.avail_in == 0)
      {
        if (consumed == body)
        {
          if (!probing)
          {
            error = "truncated compressed body: it ends after " + std::to_string(inflatedSoFar()) + " of the " +
              std::to_string(expected) + " bytes of pixel data that DimSize " + dims + " needs";
          }
          break;
        }
        const std::uint64_t n = std::min<std::uint64_t>(chunk.size(), body - consumed);
        data.read(reinterpret_cast<char*>(chunk.data()), static_cast<std::streamsize>(n));
        if (static_cast<std::uint64_t>(data.gcount()) != n)
        {
          error = "read error in " + dataPath;
          break;
        }
        consumed += n;
        z.next_in = chunk.data();
        z.avail_in = static_cast<uInt>(n);
      }
      status = inflate(&z, Z_NO_FLUSH);
      if (status != Z_OK && status != Z_STREAM_END && status != Z_BUF_ERROR)
      {
        error = std::string("corrupt compressed body (zlib: ") + (z.msg ? z.msg : "error") + ") in frame " +
          std::to_string(k) + ", after " + std::to_string(inflatedSoFar()) + " bytes of pixel data";
        break;
      }
      if (z.avail_out == 0)
      {
        if (probing)
        {
          error = "compressed body holds more than the " + std::to_string(expected) +
            " bytes of pixel data that DimSize " + dims + " describes";
          break;
        }
        store(k);
        ++k;
        this->UpdateProgress(double(k) / frames);
        if (this->AbortExecute)
        {
          inflateEnd(&z);
          output->Initialize();
          return 0;
        }
        probing = k == frames;
        z.next_out = probing ? &spare : frame.data();
        z.avail_out = probing ? 1u : static_cast<uInt>(frameBytes);
      }
    }
    if (error.empty() && k < frames)
    {
      error = "compressed body holds " + std::to_string(inflatedSoFar()) + " bytes of pixel data but DimSize " + dims +
        " needs " + std::to_string(expected);
    }
    inflateEnd(&z);
    if (!error.empty())
    {
      return fail(file + ": " + error);
    }
  }

  output->GetPointData()->SetScalars(scalars);
  vtkNew<vtkDoubleArray> poses;
  poses->SetName("ImageToReference");
  poses->SetNumberOfComponents(16);
  poses->SetNumberOfTuples(in.Count);
  vtkNew<vtkDoubleArray> stamps;
  stamps->SetName("Timestamp");
  stamps->SetNumberOfTuples(in.Count);
  vtkNew<vtkUnsignedCharArray> valid;
  valid->SetName("FrameValid");
  valid->SetNumberOfTuples(in.Count);
  vtkNew<vtkIntArray> index;
  index->SetName("FrameIndex");
  index->SetNumberOfTuples(in.Count);
  for (int f = 0; f < in.Count; ++f)
  {
    poses->SetTypedTuple(f, in.Poses[f].data());
    stamps->SetValue(f, in.Timestamps[f]);
    valid->SetValue(f, in.Valid[f]);
    index->SetValue(f, in.First + f);
  }
  output->GetFieldData()->AddArray(poses);
  output->GetFieldData()->AddArray(stamps);
  output->GetFieldData()->AddArray(valid);
  output->GetFieldData()->AddArray(index);
  return 1;
}

void vtkUltrasoundSequenceReader::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FileName: " << (this->FileName ? this->FileName : "(none)") << "\n";
  os << indent << "TransformChain: " << (this->TransformChain ? this->TransformChain : "(automatic)") << "\n";
  os << indent << "TransformChainInUse: " << this->Internals->ChainInUse << "\n";
  os << indent << "CalibrationFileName: " << (this->CalibrationFileName ? this->CalibrationFileName : "(none)") << "\n";
  os << indent << "StaticTransforms:";
  for (const auto& t : this->Internals->StaticTransforms)
  {
    os << " " << t.first;
  }
  os << "\n";
  os << indent << "FrameRange: " << this->FrameRange[0] << " " << this->FrameRange[1] << "\n";
  os << indent << "MaximumShearAngle: " << this->MaximumShearAngle << "\n";
  os << indent << "NumberOfFramesInFile: " << this->NumberOfFramesInFile << "\n";
  os << indent << "LastErrorText: " << this->Internals->LastError << "\n";
}

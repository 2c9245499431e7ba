#include "vtkUltrasoundSequenceWriter.h"

#include "bigusMetaImageHeader.h"
#include "bigusReplaceFile.h"

#include "vtkDataArray.h"
#include "vtkErrorCode.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"

#include <zlib.h>

#include <charconv>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundSequenceWriter);

namespace
{
/// Shortest decimal text that reads back to exactly @p v.
std::string Exact(double v)
{
  char buffer[64];
  auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);
  return std::string(buffer, result.ptr);
}

bool EndsWith(const std::string& s, const std::string& suffix)
{
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string BaseName(const std::string& path)
{
  const std::size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

/// Writes @p bytes to @p path in one go; false on any error.
bool WriteFile(const std::string& path, const std::string& header, const unsigned char* bytes, std::size_t n)
{
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(header.data(), static_cast<std::streamsize>(header.size()));
  out.write(reinterpret_cast<const char*>(bytes), static_cast<std::streamsize>(n));
  out.close();
  return static_cast<bool>(out);
}
}

vtkUltrasoundSequenceWriter::vtkUltrasoundSequenceWriter()
{
  this->SetTransformName("ImageToReference");
}

vtkUltrasoundSequenceWriter::~vtkUltrasoundSequenceWriter()
{
  this->SetFileName(nullptr);
  this->SetTransformName(nullptr);
}

vtkImageData* vtkUltrasoundSequenceWriter::GetInput()
{
  return vtkImageData::SafeDownCast(this->Superclass::GetInput());
}

int vtkUltrasoundSequenceWriter::FillInputPortInformation(int, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  return 1;
}

void vtkUltrasoundSequenceWriter::Fail(const std::string& message)
{
  this->LastErrorText = message;
  this->SetErrorCode(vtkErrorCode::UserError); // Write() returns 0
  vtkErrorMacro(<< message);
}

void vtkUltrasoundSequenceWriter::WriteData()
{
  this->LastErrorText.clear();
  this->SetErrorCode(vtkErrorCode::NoError);
  vtkImageData* image = this->GetInput();
  const std::string file = this->FileName ? this->FileName : "";
  if (file.empty())
  {
    return this->Fail("vtkUltrasoundSequenceWriter: no FileName set");
  }
  if (!image || !image->GetPointData()->GetScalars())
  {
    return this->Fail(file + ": the input has no image scalars to write");
  }
  vtkDataArray* scalars = image->GetPointData()->GetScalars();
  const int type = scalars->GetDataType();
  if ((type != VTK_UNSIGNED_CHAR && type != VTK_FLOAT) || scalars->GetNumberOfComponents() != 1)
  {
    return this->Fail(file + ": input scalars must be unsigned char or float with one component (got " +
      std::string(scalars->GetDataTypeAsString()) + " x " + std::to_string(scalars->GetNumberOfComponents()) + ")");
  }
  int dims[3];
  image->GetDimensions(dims);
  const int frames = dims[2];
  vtkFieldData* fd = image->GetFieldData();
  vtkDataArray* poses = fd ? fd->GetArray("ImageToReference") : nullptr;
  if (!poses || poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() != frames)
  {
    return this->Fail(file + ": field data ImageToReference must hold " + std::to_string(frames) +
      " tuples of 16 numbers (one row-major 4x4 per frame)");
  }
  vtkDataArray* stamps = fd->GetArray("Timestamp");
  vtkDataArray* valid = fd->GetArray("FrameValid");
  if ((stamps && stamps->GetNumberOfTuples() != frames) || (valid && valid->GetNumberOfTuples() != frames))
  {
    return this->Fail(
      file + ": field data Timestamp and FrameValid must hold one value per frame (" + std::to_string(frames) + ")");
  }

  const bool detached = EndsWith(file, ".mhd");
  const std::size_t bytes = std::size_t(dims[0]) * dims[1] * frames * (type == VTK_FLOAT ? 4 : 1);
  const unsigned char* pixels = static_cast<const unsigned char*>(scalars->GetVoidPointer(0));
  std::vector<unsigned char> packed;
  if (this->UseCompression)
  {
    uLongf size = compressBound(static_cast<uLong>(bytes));
    packed.resize(size);
    if (compress2(packed.data(), &size, pixels, static_cast<uLong>(bytes), this->CompressionLevel) != Z_OK)
    {
      return this->Fail(file + ": zlib compression failed");
    }
    packed.resize(size);
    pixels = packed.data();
  }
  const std::size_t bodyBytes = this->UseCompression ? packed.size() : bytes;
  std::string dataFile = "LOCAL";
  std::string dataPath;
  if (detached)
  {
    dataPath = file.substr(0, file.size() - 4) + (this->UseCompression ? ".zraw" : ".raw");
    dataFile = BaseName(dataPath);
  }

  const std::string transform =
    std::string(this->TransformName ? this->TransformName : "ImageToReference") + "Transform";
  std::ostringstream h;
  h << "ObjectType = Image\n"
    << "NDims = 3\n"
    << "AnatomicalOrientation = RAI\n"
    << "BinaryData = True\n"
    << "BinaryDataByteOrderMSB = False\n"
    << "CenterOfRotation = 0 0 0\n"
    << "CompressedData = " << (this->UseCompression ? "True" : "False") << "\n";
  if (this->UseCompression)
  {
    h << "CompressedDataSize = " << bodyBytes << "\n";
  }
  h << "DimSize = " << dims[0] << " " << dims[1] << " " << frames << "\n"
    << "ElementNumberOfChannels = 1\n"
    << "ElementSpacing = 1 1 1\n"
    << "ElementType = " << (type == VTK_FLOAT ? "MET_FLOAT" : "MET_UCHAR") << "\n"
    << "Kinds = domain domain list\n"
    << "Offset = 0 0 0\n"
    << "TransformMatrix = 1 0 0 0 1 0 0 0 1\n"
    << "UltrasoundImageOrientation = MF\n"
    << "UltrasoundImageType = BRIGHTNESS\n";
  for (int k = 0; k < frames; ++k)
  {
    double m[16];
    poses->GetTuple(k, m);
    h << bigus::FrameFieldName(k, transform) << " =";
    for (double v : m)
    {
      h << " " << Exact(v);
    }
    const bool ok = !valid || valid->GetTuple1(k) != 0;
    h << "\n"
      << bigus::FrameFieldName(k, transform + "Status") << " = " << (ok ? "OK" : "INVALID") << "\n"
      << bigus::FrameFieldName(k, "Timestamp") << " = " << Exact(stamps ? stamps->GetTuple1(k) : double(k)) << "\n"
      << bigus::FrameFieldName(k, "ImageStatus") << " = OK\n";
  }
  h << "ElementDataFile = " << dataFile << "\n";

  // Write under temporary names, then rename: an existing file is never left half-written.
  const std::string temporary = bigus::TemporaryName(file), dataTemporary = bigus::TemporaryName(dataPath);
  bool ok = true;
  if (detached)
  {
    ok = WriteFile(dataTemporary, std::string(), pixels, bodyBytes) && WriteFile(temporary, h.str(), nullptr, 0);
  }
  else
  {
    ok = WriteFile(temporary, h.str(), pixels, bodyBytes);
  }
  ok = ok && (!detached || bigus::Publish(dataTemporary, dataPath)) && bigus::Publish(temporary, file);
  if (!ok)
  {
    std::remove(temporary.c_str());
    if (detached)
    {
      std::remove(dataTemporary.c_str());
    }
    return this->Fail(file + ": cannot write the file (folder missing or not writable, or disk full)");
  }
}

void vtkUltrasoundSequenceWriter::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FileName: " << (this->FileName ? this->FileName : "(none)") << "\n";
  os << indent << "UseCompression: " << this->UseCompression << "\n";
  os << indent << "CompressionLevel: " << this->CompressionLevel << "\n";
  os << indent << "TransformName: " << (this->TransformName ? this->TransformName : "(none)") << "\n";
  os << indent << "LastErrorText: " << this->LastErrorText << "\n";
}

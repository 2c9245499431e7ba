/**
 * @file bigusMetaImageHeader.h
 * @brief Parser for the text header of MetaImage / PLUS (IGSIO) sequence metafiles.
 *
 * Private to BIGUS::Filters (no VTK types) so that the fuzz target in Testing/Fuzz can drive it
 * directly. Every error is a bigus::MetaImageError whose message names the file, the field and,
 * for per-frame fields, the frame.
 *
 * Format reference: MetaIO (https://itk.org/Wiki/MetaIO/Documentation) and the IGSIO sequence
 * metafile convention used by PLUS: per-frame fields are named Seq_Frame<NNNN>_<Field>, e.g.
 * Seq_Frame0003_ProbeToTrackerTransform (16 numbers, row-major) and
 * Seq_Frame0003_ProbeToTrackerTransformStatus (OK or INVALID).
 */
#ifndef bigusMetaImageHeader_h
#define bigusMetaImageHeader_h

#include <cstddef>
#include <cstdint>
#include <istream>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace bigus
{

/// Raised for any malformed header, unsupported value or inconsistent field.
class MetaImageError : public std::runtime_error
{
public:
  using std::runtime_error::runtime_error;
};

/// Pixel types we read and write.
enum class MetaElementType
{
  UChar,
  Float
};

/// The text header, split into global fields and per-frame (Seq_FrameNNNN_) fields.
struct MetaImageHeader
{
  std::map<std::string, std::string> Fields;                     ///< global fields
  std::map<int, std::map<std::string, std::string>> FrameFields; ///< frame -> field -> value
  std::uint64_t DataOffset = 0;                                  ///< byte offset just after the ElementDataFile line
};

/// The interpreted geometry and storage of the pixel data.
struct MetaImageLayout
{
  int Dimensions[3] = { 0, 0, 1 }; ///< columns, rows, frames
  MetaElementType ElementType = MetaElementType::UChar;
  bool Compressed = false;
  std::int64_t CompressedDataSize = -1; ///< -1 when the header does not say
  bool ByteOrderMSB = false;
  std::string ElementDataFile;    ///< "LOCAL" or a path relative to the header file
  std::string Orientation = "MF"; ///< PLUS UltrasoundImageOrientation, two letters

  std::size_t BytesPerPixel() const { return this->ElementType == MetaElementType::UChar ? 1 : 4; }
  std::uint64_t FrameBytes() const
  {
    return std::uint64_t(this->Dimensions[0]) * std::uint64_t(this->Dimensions[1]) * this->BytesPerPixel();
  }
};

/**
 * Read the header from @p in up to and including the ElementDataFile line.
 * @param where  file name used in error messages.
 * @throws MetaImageError on a line that is not "Key = Value", a repeated field, a missing
 *         ElementDataFile, or a header larger than 64 MiB.
 */
MetaImageHeader ParseMetaImageHeader(std::istream& in, const std::string& where);

/**
 * Interpret and check the global fields (NDims, DimSize, ElementType, compression, byte order,
 * channels, UltrasoundImageOrientation) and the frame numbers of per-frame fields.
 * @throws MetaImageError naming the field that is missing, malformed or unsupported.
 */
MetaImageLayout InterpretMetaImageHeader(const MetaImageHeader& header, const std::string& where);

/**
 * Parse exactly @p count whitespace-separated finite-or-not numbers (NaN/Inf are returned as such,
 * the caller decides). Returns false when the text holds a non-number or another count.
 */
bool ParseNumbers(const std::string& text, double* values, int count);

/// Name of a per-frame field in the file, e.g. FrameFieldName(3, "ProbeToTrackerTransform").
std::string FrameFieldName(int frame, const std::string& field);

/// One factor of a transform chain such as "inverse(ReferenceToTracker) * ProbeToTracker".
struct TransformTerm
{
  std::string Name; ///< without the "Transform" suffix, e.g. "ProbeToTracker"
  bool Inverse = false;
};

/**
 * Parse a transform chain: factors separated by '*', each "Name", "inverse(Name)", "inv(Name)" or
 * "Name^-1"; a trailing "Transform" on a name is dropped. The product is applied right to left to a
 * pixel, as in ImageToReference = inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe.
 * @throws MetaImageError for an empty chain, an empty factor or a name with invalid characters.
 */
std::vector<TransformTerm> ParseTransformChain(const std::string& chain);

/// Row-major 4x4 helpers (double[16]).
void MultiplyMatrix4x4(const double a[16], const double b[16], double out[16]);
/// Inverse of an affine 4x4 (bottom row 0 0 0 1); returns false when the 3x3 part is singular.
bool InvertAffine4x4(const double m[16], double out[16]);

} // namespace bigus

#endif

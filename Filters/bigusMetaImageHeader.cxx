#include "bigusMetaImageHeader.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

namespace bigus
{

namespace
{

constexpr std::uint64_t MaximumHeaderBytes = 64ull << 20;
constexpr std::size_t MaximumLineBytes = 1u << 20;

std::string Trim(const std::string& s)
{
  const char* ws = " \t\r\n\f\v";
  const std::size_t b = s.find_first_not_of(ws);
  if (b == std::string::npos)
  {
    return std::string();
  }
  const std::size_t e = s.find_last_not_of(ws);
  return s.substr(b, e - b + 1);
}

std::string Lower(std::string s)
{
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

[[noreturn]] void Fail(const std::string& where, const std::string& what)
{
  throw MetaImageError(where + ": " + what);
}

/// Printable excerpt of a value for error messages (the value may be binary garbage).
std::string Excerpt(const std::string& value)
{
  std::string out;
  for (char c : value.substr(0, 40))
  {
    out += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  }
  return value.size() > 40 ? "'" + out + "...'" : "'" + out + "'";
}

bool ParseBool(const std::string& value, bool& out)
{
  const std::string v = Lower(value);
  if (v == "true" || v == "1")
  {
    out = true;
    return true;
  }
  if (v == "false" || v == "0")
  {
    out = false;
    return true;
  }
  return false;
}

/// Splits "Seq_Frame0012_ProbeToTrackerTransform" into 12 and "ProbeToTrackerTransform".
bool SplitFrameKey(const std::string& key, int& frame, std::string& field)
{
  static const std::string prefix = "Seq_Frame";
  if (key.compare(0, prefix.size(), prefix) != 0)
  {
    return false;
  }
  std::size_t p = prefix.size();
  std::size_t q = p;
  while (q < key.size() && std::isdigit(static_cast<unsigned char>(key[q])))
  {
    ++q;
  }
  if (q == p || q - p > 9 || q >= key.size() || key[q] != '_' || q + 1 >= key.size())
  {
    return false;
  }
  frame = std::stoi(key.substr(p, q - p));
  field = key.substr(q + 1);
  return true;
}

} // namespace

MetaImageHeader ParseMetaImageHeader(std::istream& in, const std::string& where)
{
  MetaImageHeader header;
  std::map<std::string, int> seenAt;
  std::string line;
  std::uint64_t offset = 0;
  int lineNumber = 0;
  while (true)
  {
    line.clear();
    char c;
    bool gotNewline = false;
    while (in.get(c))
    {
      if (c == '\n')
      {
        gotNewline = true;
        break;
      }
      line.push_back(c);
      if (line.size() > MaximumLineBytes)
      {
        Fail(where,
          "header line " + std::to_string(lineNumber + 1) +
            " is longer than 1 MiB (binary data before ElementDataFile?)");
      }
    }
    if (!gotNewline && line.empty())
    {
      Fail(where, "header has no ElementDataFile field (file ends after " + std::to_string(lineNumber) + " lines)");
    }
    ++lineNumber;
    offset += line.size() + (gotNewline ? 1 : 0);
    if (offset > MaximumHeaderBytes)
    {
      Fail(where, "header is larger than 64 MiB without an ElementDataFile field");
    }
    const std::string trimmed = Trim(line);
    if (trimmed.empty())
    {
      continue;
    }
    const std::size_t eq = trimmed.find('=');
    if (eq == std::string::npos)
    {
      Fail(where,
        "header line " + std::to_string(lineNumber) + " is not 'Key = Value': " + Excerpt(trimmed) +
          " (binary data or a cut before the ElementDataFile field?)");
    }
    const std::string key = Trim(trimmed.substr(0, eq));
    const std::string value = Trim(trimmed.substr(eq + 1));
    if (key.empty())
    {
      Fail(where, "header line " + std::to_string(lineNumber) + " has an empty field name");
    }
    auto seen = seenAt.emplace(key, lineNumber);
    if (!seen.second)
    {
      Fail(where,
        "field " + key + " appears twice (lines " + std::to_string(seen.first->second) + " and " +
          std::to_string(lineNumber) + ")");
    }
    int frame = 0;
    std::string field;
    if (SplitFrameKey(key, frame, field))
    {
      // Frames are matched by number: Seq_Frame1_X and Seq_Frame0001_X name one field of one frame.
      if (!header.FrameFields[frame].emplace(field, value).second)
      {
        Fail(where,
          "field " + key + " (line " + std::to_string(lineNumber) + ") names the " + field + " of frame " +
            std::to_string(frame) + " a second time, under another number's spelling");
      }
    }
    else
    {
      header.Fields[key] = value;
    }
    if (key == "ElementDataFile")
    {
      header.DataOffset = offset;
      return header;
    }
    if (!gotNewline)
    {
      Fail(where, "header has no ElementDataFile field (file ends after " + std::to_string(lineNumber) + " lines)");
    }
  }
}

MetaImageLayout InterpretMetaImageHeader(const MetaImageHeader& header, const std::string& where)
{
  MetaImageLayout layout;
  auto find = [&](const char* key) -> const std::string* {
    auto it = header.Fields.find(key);
    return it == header.Fields.end() ? nullptr : &it->second;
  };
  auto require = [&](const char* key) -> const std::string& {
    const std::string* v = find(key);
    if (!v)
    {
      Fail(where, std::string("required field ") + key + " is missing");
    }
    return *v;
  };

  if (const std::string* v = find("ObjectType"))
  {
    if (Lower(*v) != "image")
    {
      Fail(where, "field ObjectType is " + Excerpt(*v) + ", expected Image");
    }
  }
  const std::string& ndimsText = require("NDims");
  double ndimsValue = 0;
  if (!ParseNumbers(ndimsText, &ndimsValue, 1) || (ndimsValue != 2 && ndimsValue != 3))
  {
    Fail(where, "field NDims is " + Excerpt(ndimsText) + ", expected 2 (one frame) or 3 (a sequence)");
  }
  const int ndims = static_cast<int>(ndimsValue);

  const std::string& dimText = require("DimSize");
  double dims[3] = { 0, 0, 1 };
  if (!ParseNumbers(dimText, dims, ndims))
  {
    Fail(where, "field DimSize is " + Excerpt(dimText) + ", expected " + std::to_string(ndims) + " positive integers");
  }
  for (int k = 0; k < 3; ++k)
  {
    if (!(dims[k] >= 1 && dims[k] <= 1e7) || dims[k] != std::floor(dims[k]))
    {
      Fail(where, "field DimSize is " + Excerpt(dimText) + ", expected positive integers");
    }
    layout.Dimensions[k] = static_cast<int>(dims[k]);
  }
  const std::uint64_t voxels =
    std::uint64_t(layout.Dimensions[0]) * std::uint64_t(layout.Dimensions[1]) * std::uint64_t(layout.Dimensions[2]);
  if (voxels > (std::uint64_t(1) << 36))
  {
    Fail(where, "field DimSize " + Excerpt(dimText) + " describes more than 2^36 pixels");
  }
  if (std::uint64_t(layout.Dimensions[0]) * std::uint64_t(layout.Dimensions[1]) > (std::uint64_t(1) << 28))
  {
    Fail(where, "field DimSize " + Excerpt(dimText) + " describes frames of more than 2^28 pixels");
  }

  if (const std::string* v = find("ElementNumberOfChannels"))
  {
    double channels = 0;
    if (!ParseNumbers(*v, &channels, 1) || channels != 1)
    {
      Fail(where,
        "field ElementNumberOfChannels is " + Excerpt(*v) + "; only single-channel (B-mode) frames are supported");
    }
  }
  const std::string& type = require("ElementType");
  if (type == "MET_UCHAR")
  {
    layout.ElementType = MetaElementType::UChar;
  }
  else if (type == "MET_FLOAT")
  {
    layout.ElementType = MetaElementType::Float;
  }
  else
  {
    Fail(where, "field ElementType is " + Excerpt(type) + "; supported: MET_UCHAR, MET_FLOAT");
  }

  if (const std::string* v = find("BinaryData"))
  {
    bool binary = true;
    if (!ParseBool(*v, binary) || !binary)
    {
      Fail(where, "field BinaryData is " + Excerpt(*v) + "; only binary pixel data is supported");
    }
  }
  for (const char* key : { "BinaryDataByteOrderMSB", "ElementByteOrderMSB" })
  {
    if (const std::string* v = find(key))
    {
      if (!ParseBool(*v, layout.ByteOrderMSB))
      {
        Fail(where, std::string("field ") + key + " is " + Excerpt(*v) + ", expected True or False");
      }
    }
  }
  if (const std::string* v = find("CompressedData"))
  {
    if (!ParseBool(*v, layout.Compressed))
    {
      Fail(where, "field CompressedData is " + Excerpt(*v) + ", expected True or False");
    }
  }
  if (const std::string* v = find("CompressedDataSize"))
  {
    double size = -1;
    if (!ParseNumbers(*v, &size, 1) || !(size >= 0 && size < 9e15) || size != std::floor(size))
    {
      Fail(where, "field CompressedDataSize is " + Excerpt(*v) + ", expected a byte count");
    }
    layout.CompressedDataSize = static_cast<std::int64_t>(size);
  }
  if (const std::string* v = find("HeaderSize"))
  {
    double size = 0;
    if (!ParseNumbers(*v, &size, 1) || size != 0)
    {
      Fail(where, "field HeaderSize is " + Excerpt(*v) + "; only HeaderSize = 0 is supported");
    }
  }

  const std::string& dataFile = require("ElementDataFile");
  if (dataFile.empty())
  {
    Fail(where, "field ElementDataFile is empty");
  }
  if (Lower(dataFile) == "list" || dataFile.find('%') != std::string::npos)
  {
    Fail(where,
      "field ElementDataFile is " + Excerpt(dataFile) +
        "; lists of data files are not supported, use LOCAL or one .raw/.zraw file");
  }
  layout.ElementDataFile = dataFile == "LOCAL" || dataFile == "Local" ? std::string("LOCAL") : dataFile;

  if (const std::string* v = find("UltrasoundImageOrientation"))
  {
    // PLUS codes: first letter M/U (image x axis towards the Marked/Unmarked side of the
    // transducer), second F/N (image y axis towards Far/Near), optional third for the frame axis.
    const std::string& o = *v;
    const bool ok =
      (o.size() == 2 || (o.size() == 3 && o[2] == 'A')) && (o[0] == 'M' || o[0] == 'U') && (o[1] == 'F' || o[1] == 'N');
    if (!ok)
    {
      Fail(where,
        "field UltrasoundImageOrientation is " + Excerpt(o) + "; supported: MF, MN, UF, UN (optionally followed by A)");
    }
    layout.Orientation = o.substr(0, 2);
  }

  if (!header.FrameFields.empty() && header.FrameFields.rbegin()->first >= layout.Dimensions[2])
  {
    const int frame = header.FrameFields.rbegin()->first;
    Fail(where,
      "frame " + std::to_string(frame) + ": field " +
        FrameFieldName(frame, header.FrameFields.rbegin()->second.begin()->first) + " is beyond the " +
        std::to_string(layout.Dimensions[2]) + " frames of DimSize");
  }
  return layout;
}

bool ParseNumbers(const std::string& text, double* values, int count)
{
  const char* p = text.data();
  const char* end = text.data() + text.size();
  for (int k = 0; k < count; ++k)
  {
    while (p < end && std::isspace(static_cast<unsigned char>(*p)))
    {
      ++p;
    }
    if (p == end)
    {
      return false;
    }
    const char* start = p;
    if (*p == '+')
    {
      ++start; // from_chars does not accept a leading '+'
    }
    auto result = std::from_chars(start, end, values[k]);
    if (result.ec == std::errc::result_out_of_range)
    {
      // Overflowing literals such as 1e999 are read as +-Inf, which the caller rejects with a clear message.
      values[k] = (*start == '-') ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
    }
    else if (result.ec != std::errc())
    {
      return false;
    }
    p = result.ptr;
    if (p < end && !std::isspace(static_cast<unsigned char>(*p)))
    {
      return false;
    }
  }
  while (p < end && std::isspace(static_cast<unsigned char>(*p)))
  {
    ++p;
  }
  return p == end;
}

std::string FrameFieldName(int frame, const std::string& field)
{
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "Seq_Frame%04d_", frame);
  return buffer + field;
}

std::vector<TransformTerm> ParseTransformChain(const std::string& chain)
{
  std::vector<TransformTerm> terms;
  std::stringstream stream(chain);
  std::string factor;
  auto bad = [&](const std::string& why) { throw MetaImageError("transform chain '" + chain + "': " + why); };
  while (std::getline(stream, factor, '*'))
  {
    std::string f = Trim(factor);
    TransformTerm term;
    for (const char* prefix : { "inverse(", "inv(" })
    {
      const std::size_t n = std::char_traits<char>::length(prefix);
      if (f.size() > n && f.compare(0, n, prefix) == 0)
      {
        if (f.back() != ')')
        {
          bad("missing ')' in factor '" + f + "'");
        }
        f = Trim(f.substr(n, f.size() - n - 1));
        term.Inverse = true;
        break;
      }
    }
    if (!term.Inverse && f.size() > 3 && f.compare(f.size() - 3, 3, "^-1") == 0)
    {
      f = Trim(f.substr(0, f.size() - 3));
      term.Inverse = true;
    }
    if (f.size() > 9 && f.compare(f.size() - 9, 9, "Transform") == 0)
    {
      f = f.substr(0, f.size() - 9);
    }
    if (f.empty())
    {
      bad("empty factor");
    }
    for (char c : f)
    {
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_'))
      {
        bad("invalid character '" + std::string(1, c) + "' in transform name '" + f + "'");
      }
    }
    term.Name = f;
    terms.push_back(term);
  }
  if (terms.empty() || Trim(chain).back() == '*')
  {
    bad("expected factors separated by '*'");
  }
  return terms;
}

void MultiplyMatrix4x4(const double a[16], const double b[16], double out[16])
{
  double r[16];
  for (int i = 0; i < 4; ++i)
  {
    for (int j = 0; j < 4; ++j)
    {
      r[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j] + a[4 * i + 3] * b[12 + j];
    }
  }
  std::copy(r, r + 16, out);
}

bool InvertAffine4x4(const double m[16], double out[16])
{
  const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], k = m[10];
  const double c00 = e * k - f * h, c01 = c * h - b * k, c02 = b * f - c * e;
  const double det = a * c00 + d * c01 + g * c02;
  const double scale = std::abs(a) + std::abs(b) + std::abs(c) + std::abs(d) + std::abs(e) + std::abs(f) + std::abs(g) +
    std::abs(h) + std::abs(k);
  if (!std::isfinite(det) || std::abs(det) <= 1e-12 * scale * scale * scale)
  {
    return false;
  }
  double r[16] = { c00 / det, c01 / det, c02 / det, 0, (f * g - d * k) / det, (a * k - c * g) / det,
    (c * d - a * f) / det, 0, (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det, 0, 0, 0, 0, 1 };
  for (int i = 0; i < 3; ++i)
  {
    r[4 * i + 3] = -(r[4 * i] * m[3] + r[4 * i + 1] * m[7] + r[4 * i + 2] * m[11]);
  }
  std::copy(r, r + 16, out);
  return true;
}

} // namespace bigus

// libFuzzer entry point: any byte string given as a sequence metafile header must either parse or
// raise bigus::MetaImageError; never crash, hang, leak or trip a sanitizer. Exercises the same steps
// as vtkUltrasoundSequenceReader::RequestInformation: header, layout, per-frame matrices, statuses,
// timestamps, the transform chain syntax and the pose check.
#include "bigusMetaImageHeader.h"
#include "bigusSliceFrame.h"

#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try
  {
    std::istringstream in(bytes);
    const bigus::MetaImageHeader header = bigus::ParseMetaImageHeader(in, "fuzz");
    const bigus::MetaImageLayout layout = bigus::InterpretMetaImageHeader(header, "fuzz");
    (void)layout.FrameBytes();
    for (const auto& frame : header.FrameFields)
    {
      for (const auto& field : frame.second)
      {
        double m[16];
        if (bigus::ParseNumbers(field.second, m, 16))
        {
          double inverse[16], product[16];
          if (bigus::InvertAffine4x4(m, inverse))
          {
            bigus::MultiplyMatrix4x4(m, inverse, product);
          }
          bigus::SliceFrame slice;
          (void)bigus::ComputeSliceFrame(m, 5.0, slice);
        }
        double t;
        (void)bigus::ParseNumbers(field.second, &t, 1);
      }
    }
  }
  catch (const bigus::MetaImageError&)
  {}
  // The first line doubles as a transform chain.
  try
  {
    (void)bigus::ParseTransformChain(bytes.substr(0, bytes.find('\n')));
  }
  catch (const bigus::MetaImageError&)
  {}
  return 0;
}

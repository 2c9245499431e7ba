#include "vtkUltrasoundCalibration.h"

#include "bigusMetaImageHeader.h"

#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkXMLDataElement.h"
#include "vtkXMLDataParser.h"
#include "vtkCommand.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

class vtkUltrasoundCalibration::vtkInternals
{
public:
  struct Transform
  {
    std::string From, To, Name;
    double Matrix[16];
  };
  std::vector<Transform> Transforms;
  std::string ErrorText;
};

vtkStandardNewMacro(vtkUltrasoundCalibration);

vtkUltrasoundCalibration::vtkUltrasoundCalibration()
  : Internals(new vtkInternals)
{}

vtkUltrasoundCalibration::~vtkUltrasoundCalibration()
{
  this->SetFileName(nullptr);
}

namespace
{
void FindElements(vtkXMLDataElement* element, const char* name, std::vector<vtkXMLDataElement*>& found)
{
  for (int i = 0; i < element->GetNumberOfNestedElements(); ++i)
  {
    vtkXMLDataElement* child = element->GetNestedElement(i);
    if (child->GetName() && std::string(child->GetName()) == name)
    {
      found.push_back(child);
    }
    FindElements(child, name, found);
  }
}

/// Swallows the XML parser's own error output; Parse() reports one clear message instead.
class ErrorCatcher : public vtkCommand
{
public:
  static ErrorCatcher* New() { return new ErrorCatcher; }
  void Execute(vtkObject*, unsigned long, void* data) override
  {
    if (data && this->Text.empty())
    {
      this->Text = static_cast<const char*>(data);
      while (!this->Text.empty() && (this->Text.back() == '\n' || this->Text.back() == ' '))
      {
        this->Text.pop_back();
      }
    }
  }
  std::string Text;
};
}

bool vtkUltrasoundCalibration::Parse()
{
  vtkInternals& internals = *this->Internals;
  internals.Transforms.clear();
  internals.ErrorText.clear();
  this->HasClipRectangle = false;
  this->HasFan = false;
  this->Modified();
  const std::string file = this->FileName ? this->FileName : "";
  auto fail = [&](const std::string& what) {
    internals.Transforms.clear();
    this->HasClipRectangle = false;
    this->HasFan = false;
    internals.ErrorText = file + ": " + what;
    return false;
  };
  if (file.empty())
  {
    internals.ErrorText = "vtkUltrasoundCalibration: no FileName set";
    return false;
  }
  if (!std::ifstream(file).good())
  {
    return fail("cannot open the calibration file");
  }
  vtkNew<vtkXMLDataParser> parser;
  vtkNew<ErrorCatcher> catcher;
  parser->AddObserver(vtkCommand::ErrorEvent, catcher);
  parser->SetFileName(file.c_str());
  if (!parser->Parse() || !parser->GetRootElement())
  {
    return fail("malformed XML" + (catcher->Text.empty() ? std::string() : " (" + catcher->Text + ")"));
  }
  vtkXMLDataElement* root = parser->GetRootElement();

  std::vector<vtkXMLDataElement*> transforms;
  FindElements(root, "Transform", transforms);
  for (vtkXMLDataElement* t : transforms)
  {
    const char* from = t->GetAttribute("From");
    const char* to = t->GetAttribute("To");
    const char* matrix = t->GetAttribute("Matrix");
    const std::string label =
      std::string("<Transform From=\"") + (from ? from : "?") + "\" To=\"" + (to ? to : "?") + "\">";
    if (!from || !to || !*from || !*to)
    {
      return fail(label + " needs both From and To attributes");
    }
    vtkInternals::Transform entry;
    entry.From = from;
    entry.To = to;
    entry.Name = entry.From + "To" + entry.To;
    if (!matrix || !bigus::ParseNumbers(matrix, entry.Matrix, 16))
    {
      return fail(label + ": attribute Matrix must hold 16 numbers (row-major 4x4)");
    }
    for (double v : entry.Matrix)
    {
      if (!std::isfinite(v))
      {
        return fail(label + ": attribute Matrix holds NaN or Inf");
      }
    }
    double inverse[16];
    if (!bigus::InvertAffine4x4(entry.Matrix, inverse))
    {
      return fail(label + ": Matrix is singular or not affine");
    }
    // A pair given twice (either way round) must say the same thing: which one a lookup finds is not the user's.
    bool repeated = false;
    for (const vtkInternals::Transform& earlier : internals.Transforms)
    {
      const bool same = earlier.From == entry.From && earlier.To == entry.To;
      if (!same && !(earlier.From == entry.To && earlier.To == entry.From))
      {
        continue;
      }
      double other[16];
      std::copy_n(earlier.Matrix, 16, other);
      if (!same)
      {
        bigus::InvertAffine4x4(earlier.Matrix, other);
      }
      for (int k = 0; k < 16; ++k)
      {
        if (std::abs(other[k] - entry.Matrix[k]) > 1e-6 * (1 + std::abs(entry.Matrix[k])))
        {
          return fail(label + " conflicts with the " + earlier.From + "To" + earlier.To +
            " given before it (their matrices differ; remove one)");
        }
      }
      repeated = true;
    }
    if (!repeated)
    {
      internals.Transforms.push_back(entry);
    }
  }

  std::vector<vtkXMLDataElement*> reconstruction;
  FindElements(root, "VolumeReconstruction", reconstruction);
  if (!reconstruction.empty())
  {
    vtkXMLDataElement* r = reconstruction.front();
    auto numbers = [&](const char* name, double* out, int count) -> int {
      const char* text = r->GetAttribute(name);
      if (!text)
      {
        return 0;
      }
      if (!bigus::ParseNumbers(text, out, count))
      {
        return -1;
      }
      for (int k = 0; k < count; ++k)
      {
        if (!std::isfinite(out[k]))
        {
          return -1;
        }
      }
      return 1;
    };
    double origin[2], size[2];
    const int hasOrigin = numbers("ClipRectangleOrigin", origin, 2);
    const int hasSize = numbers("ClipRectangleSize", size, 2);
    if (hasOrigin < 0 || hasSize < 0 || hasOrigin != hasSize ||
      (hasSize > 0 && (size[0] < 1 || size[1] < 1 || origin[0] < 0 || origin[1] < 0)))
    {
      return fail("<VolumeReconstruction>: ClipRectangleOrigin and ClipRectangleSize must both be given as "
                  "two non-negative integers (size at least 1)");
    }
    if (hasSize > 0)
    {
      this->HasClipRectangle = true;
      for (int k = 0; k < 2; ++k)
      {
        this->ClipRectangleOrigin[k] = static_cast<int>(origin[k]);
        this->ClipRectangleSize[k] = static_cast<int>(size[k]);
      }
    }
    double angles[2], apex[2], r0 = 0, r1 = 0;
    const int hasAngles = numbers("FanAnglesDeg", angles, 2);
    const int hasApex = numbers("FanOriginPixel", apex, 2);
    const int hasR0 = numbers("FanRadiusStartPixel", &r0, 1);
    const int hasR1 = numbers("FanRadiusStopPixel", &r1, 1);
    if (hasAngles < 0 || hasApex < 0 || hasR0 < 0 || hasR1 < 0 || hasAngles != hasApex ||
      (hasAngles > 0 && !(angles[0] < angles[1] && angles[0] >= -90 && angles[1] <= 90)) || r0 < 0 || r1 < 0)
    {
      return fail("<VolumeReconstruction>: fan needs FanAnglesDeg (min < max, within -90..90) and "
                  "FanOriginPixel together; FanRadiusStartPixel/FanRadiusStopPixel must be >= 0");
    }
    if (hasAngles > 0)
    {
      this->HasFan = true;
      this->FanAngles[0] = angles[0];
      this->FanAngles[1] = angles[1];
      this->FanOrigin[0] = apex[0];
      this->FanOrigin[1] = apex[1];
      this->FanRadius[0] = r0;
      this->FanRadius[1] = r1;
    }
  }
  return true;
}

const char* vtkUltrasoundCalibration::GetErrorText() const
{
  return this->Internals->ErrorText.c_str();
}

int vtkUltrasoundCalibration::GetNumberOfTransforms() const
{
  return static_cast<int>(this->Internals->Transforms.size());
}

const char* vtkUltrasoundCalibration::GetTransformName(int i) const
{
  if (i < 0 || i >= this->GetNumberOfTransforms())
  {
    return nullptr;
  }
  return this->Internals->Transforms[i].Name.c_str();
}

bool vtkUltrasoundCalibration::GetTransform(const char* from, const char* to, vtkMatrix4x4* matrix) const
{
  if (!from || !to)
  {
    return false;
  }
  return this->GetTransform((std::string(from) + "To" + to).c_str(), matrix);
}

bool vtkUltrasoundCalibration::GetTransform(const char* name, vtkMatrix4x4* matrix) const
{
  if (!name || !matrix)
  {
    return false;
  }
  for (const auto& t : this->Internals->Transforms)
  {
    if (t.Name == name)
    {
      matrix->DeepCopy(t.Matrix);
      return true;
    }
    if (t.To + "To" + t.From == name)
    {
      double inverse[16];
      bigus::InvertAffine4x4(t.Matrix, inverse); // checked invertible in Parse()
      matrix->DeepCopy(inverse);
      return true;
    }
  }
  return false;
}

void vtkUltrasoundCalibration::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FileName: " << (this->FileName ? this->FileName : "(none)") << "\n";
  os << indent << "Transforms:";
  for (const auto& t : this->Internals->Transforms)
  {
    os << " " << t.Name;
  }
  os << "\n";
  os << indent << "HasClipRectangle: " << this->HasClipRectangle << " origin " << this->ClipRectangleOrigin[0] << " "
     << this->ClipRectangleOrigin[1] << " size " << this->ClipRectangleSize[0] << " " << this->ClipRectangleSize[1]
     << "\n";
  os << indent << "HasFan: " << this->HasFan << " angles " << this->FanAngles[0] << " " << this->FanAngles[1]
     << " origin " << this->FanOrigin[0] << " " << this->FanOrigin[1] << " radius " << this->FanRadius[0] << " "
     << this->FanRadius[1] << "\n";
  os << indent << "ErrorText: " << this->Internals->ErrorText << "\n";
}

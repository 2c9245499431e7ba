#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkObject.h"
#include "vtkUnsignedCharArray.h"

#include <fstream>
#include <sstream>

namespace bigus_test
{
std::string DataPath(const std::string& relative)
{
  return std::string(BIGUS_TEST_DATA) + "/" + relative;
}

std::string ExamplePath(const std::string& relative)
{
  return std::string(BIGUS_EXAMPLE_DATA) + "/" + relative;
}

std::string OutputPath(const std::string& name)
{
  return std::string(BIGUS_TEST_OUTPUT) + "/" + name;
}

vtkSmartPointer<vtkImageData> TrackedSequence(int w, int h, const std::vector<std::array<double, 16>>& poses,
  const std::vector<double>& times, const std::function<float(int, int, int)>& value)
{
  const int n = static_cast<int>(poses.size());
  auto image = vtkSmartPointer<vtkImageData>::New();
  image->SetDimensions(w, h, n);
  image->AllocateScalars(VTK_FLOAT, 1);
  auto* p = static_cast<float*>(image->GetScalarPointer());
  vtkNew<vtkDoubleArray> pose, stamp;
  pose->SetName("ImageToReference");
  pose->SetNumberOfComponents(16);
  pose->SetNumberOfTuples(n);
  stamp->SetName("Timestamp");
  stamp->SetNumberOfTuples(n);
  vtkNew<vtkUnsignedCharArray> valid;
  valid->SetName("FrameValid");
  valid->SetNumberOfTuples(n);
  for (int k = 0; k < n; ++k)
  {
    for (int j = 0; j < h; ++j)
    {
      for (int i = 0; i < w; ++i)
      {
        p[(std::size_t(k) * h + j) * w + i] = value(k, i, j);
      }
    }
    pose->SetTuple(k, poses[k].data());
    stamp->SetValue(k, times[k]);
    valid->SetValue(k, 1);
  }
  image->GetFieldData()->AddArray(pose);
  image->GetFieldData()->AddArray(stamp);
  image->GetFieldData()->AddArray(valid);
  return image;
}

std::array<double, 16> Pose(vtkImageData* sequence, int k)
{
  std::array<double, 16> m{};
  sequence->GetFieldData()->GetArray("ImageToReference")->GetTuple(k, m.data());
  return m;
}

void MessageCollector::Execute(vtkObject*, unsigned long event, void* data)
{
  const std::string text = data ? static_cast<const char*>(data) : "";
  (event == vtkCommand::ErrorEvent ? this->Errors : this->Warnings).push_back(text);
}

void MessageCollector::Watch(vtkObject* object)
{
  object->AddObserver(vtkCommand::ErrorEvent, this);
  object->AddObserver(vtkCommand::WarningEvent, this);
}

std::string ReadFileBytes(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}
}

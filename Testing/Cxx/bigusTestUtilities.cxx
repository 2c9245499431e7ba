#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkObject.h"

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

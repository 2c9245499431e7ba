// Shared helpers for the BIGUS GoogleTest suites: data paths, pose access, capture of VTK errors.
#ifndef bigusTestUtilities_h
#define bigusTestUtilities_h

#include "vtkCommand.h"
#include "vtkSmartPointer.h"

#include <array>
#include <functional>
#include <string>
#include <vector>

class vtkAlgorithm;
class vtkImageData;
class vtkObject;

namespace bigus_test
{
/// Path of a file under Testing/Data.
std::string DataPath(const std::string& relative);
/// Path of a file under Examples/Data.
std::string ExamplePath(const std::string& relative);
/// Path for a file a test writes (under the build tree); the folder exists.
std::string OutputPath(const std::string& name);

/// Row-major ImageToReference of frame k of a tracked sequence.
std::array<double, 16> Pose(vtkImageData* sequence, int k);

/**
 * A tracked frame sequence (DESIGN section 2) of W x H float frames with the given poses (row-major
 * ImageToReference) and timestamps (s), FrameValid 1 and no FrameIndex; pixel (i, j) of frame k has
 * value(k, i, j).
 */
vtkSmartPointer<vtkImageData> TrackedSequence(int w, int h, const std::vector<std::array<double, 16>>& poses,
  const std::vector<double>& times, const std::function<float(int, int, int)>& value);

/// Collects the messages of vtkErrorMacro / vtkWarningMacro of the objects it observes.
class MessageCollector : public vtkCommand
{
public:
  static MessageCollector* New() { return new MessageCollector; }
  void Execute(vtkObject*, unsigned long event, void* data) override;
  /// Observe ErrorEvent and WarningEvent of @p object.
  void Watch(vtkObject* object);
  std::vector<std::string> Errors;
  std::vector<std::string> Warnings;
};

/// Bytes of a whole file (empty if it cannot be read).
std::string ReadFileBytes(const std::string& path);
}

#endif

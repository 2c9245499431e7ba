// Screenshot regression tests of what a viewer shows of the committed reference field
// (Testing/Data/Reference/nwire_reference.vtp), compared with Testing/Data/Baseline by VTK's
// vtkRegressionTestImage at its default threshold:
//   slice   the "oblique" plane of reference.json, rendered by vtkGaussianFieldReslice and shown whole
//           through a vtkImageActor, depth downwards;
//   volume  the "volume" grid of reference.json (OutputDimensionality 3, 0.5 mm) composited by
//           vtkFixedPointVolumeRayCastMapper: CPU ray casting, so that the picture depends on neither
//           the OpenGL driver nor the render time.
// The data themselves are checked far more tightly by TestReferenceResults (1e-5 per pixel). Measured
// when the baselines were made, with the reslice axes moved: the slice fails from 0.3 mm along its
// normal (0.2 mm passes), the volume from 0.5 mm along z or x (0.3 mm passes).
//
// Usage: TestGaussianFieldRegressionImages slice|volume -V <baseline.png> -T <output folder> [-I]
// Exits 125 (skipped) without a DISPLAY: Debian's VTK renders only through X (DESIGN section 8).
// To regenerate a baseline after a deliberate change of rendering: delete it and run the test once
// (`xvfb-run -a ctest --test-dir build -R RegressionImage`); vtkTesting writes the new image under the
// baseline's name to build/Testing/Output and fails. Look at it, then copy it to Testing/Data/Baseline.
#include "bigusReferenceGeometry.h"
#include "bigusTestUtilities.h"

#include "vtkCamera.h"
#include "vtkColorTransferFunction.h"
#include "vtkFixedPointVolumeRayCastMapper.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkImageActor.h"
#include "vtkImageData.h"
#include "vtkImageMapper3D.h"
#include "vtkImageProperty.h"
#include "vtkNew.h"
#include "vtkPiecewiseFunction.h"
#include "vtkRegressionTestImage.h"
#include "vtkRenderWindow.h"
#include "vtkRenderWindowInteractor.h"
#include "vtkRenderer.h"
#include "vtkVolume.h"
#include "vtkVolumeProperty.h"
#include "vtkXMLPolyDataReader.h"

#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace
{
constexpr int WindowWidth = 300;
constexpr int WindowHeight = 225;

/// The committed field rendered with the geometry @p name of reference.json's "planes" (the ones that
/// TestReferenceResults replays; entries left out keep the filter's defaults). Null, with a message,
/// on failure.
vtkSmartPointer<vtkGaussianFieldReslice> ReferenceReslice(const std::string& name)
{
  const std::string path = bigus_test::DataPath("Reference/reference.json");
  std::ifstream in(path);
  const auto reference = nlohmann::json::parse(in, nullptr, false);
  nlohmann::json geometry;
  if (reference.is_object() && reference.contains("planes"))
  {
    for (const auto& plane : reference["planes"])
    {
      if (plane.value("name", "") == name)
      {
        geometry = plane;
      }
    }
  }
  if (geometry.is_null())
  {
    std::cerr << path << " has no geometry named " << name << "\n";
    return nullptr;
  }

  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(bigus_test::DataPath("Reference/nwire_reference.vtp").c_str());
  auto reslice = vtkSmartPointer<vtkGaussianFieldReslice>::New();
  reslice->SetInputConnection(reader->GetOutputPort());
  reslice->OutputCoverageOff();
  bigus_test::ApplyReferenceGeometry(reslice, geometry);
  reslice->Update();
  if (reslice->GetOutput()->GetNumberOfPoints() == 0)
  {
    std::cerr << "vtkGaussianFieldReslice rendered nothing for the geometry " << name << "\n";
    return nullptr;
  }
  return reslice;
}

/// Black, red, yellow, white over intensities [0, 1]. Each channel spans a third of the range, three
/// times the slope of a grey ramp: vtkImageDifference forgives 105 of 255 per channel after a shift of
/// up to two pixels, which on a grey ramp hides an intensity change of 0.4.
vtkSmartPointer<vtkColorTransferFunction> HotColors()
{
  auto colors = vtkSmartPointer<vtkColorTransferFunction>::New();
  colors->AddRGBPoint(0.0, 0.0, 0.0, 0.0);
  colors->AddRGBPoint(1.0 / 3.0, 1.0, 0.0, 0.0);
  colors->AddRGBPoint(2.0 / 3.0, 1.0, 1.0, 0.0);
  colors->AddRGBPoint(1.0, 1.0, 1.0, 1.0);
  return colors;
}

/// The whole oblique plane, as an ultrasound image is shown: depth (the image's y) downwards.
bool AddSlice(vtkRenderer* renderer)
{
  auto reslice = ReferenceReslice("oblique");
  if (!reslice)
  {
    return false;
  }
  vtkNew<vtkImageActor> actor;
  actor->GetMapper()->SetInputConnection(reslice->GetOutputPort());
  actor->GetProperty()->SetLookupTable(HotColors());
  actor->GetProperty()->UseLookupTableScalarRangeOn();
  renderer->AddViewProp(actor);

  // The image lies in its plane's coordinates (mm), z = 0.
  double bounds[6];
  reslice->GetOutput()->GetBounds(bounds);
  const double x = 0.5 * (bounds[0] + bounds[1]);
  const double y = 0.5 * (bounds[2] + bounds[3]);
  vtkCamera* camera = renderer->GetActiveCamera();
  camera->ParallelProjectionOn();
  camera->SetFocalPoint(x, y, 0.0);
  camera->SetPosition(x, y, -100.0);
  camera->SetViewUp(0.0, -1.0, 0.0);
  camera->SetParallelScale(0.5 * (bounds[3] - bounds[2]));
  renderer->ResetCameraClippingRange();
  return true;
}

/// The field's default grid as a volume: the wire that it holds, seen across.
bool AddVolume(vtkRenderer* renderer)
{
  auto reslice = ReferenceReslice("volume");
  if (!reslice)
  {
    return false;
  }
  vtkNew<vtkFixedPointVolumeRayCastMapper> mapper;
  mapper->SetInputConnection(reslice->GetOutputPort());
  mapper->AutoAdjustSampleDistancesOff(); // else the sample distance follows the render time
  mapper->SetSampleDistance(0.25);        // mm, half a voxel

  vtkNew<vtkPiecewiseFunction> opacity;
  opacity->AddPoint(0.05, 0.0);
  opacity->AddPoint(0.4, 1.0);
  vtkNew<vtkVolume> volume;
  volume->SetMapper(mapper);
  volume->GetProperty()->SetScalarOpacity(opacity);
  volume->GetProperty()->SetScalarOpacityUnitDistance(0.5);
  volume->GetProperty()->SetColor(HotColors());
  volume->GetProperty()->SetInterpolationTypeToLinear();
  renderer->AddViewProp(volume);

  // Fixed in the reference frame (mm) rather than fitted to the data, so that a field or grid that
  // moves shows as a moved picture.
  vtkCamera* camera = renderer->GetActiveCamera();
  camera->SetFocalPoint(19.3, -93.2, -32.9);
  camera->SetPosition(49.3, -183.2, -12.9);
  camera->SetViewUp(0.0, 0.0, 1.0);
  camera->SetViewAngle(12.0);
  renderer->ResetCameraClippingRange();
  return true;
}
}

int main(int argc, char* argv[])
{
  const std::string view = argc > 1 ? argv[1] : "";
  if (view != "slice" && view != "volume")
  {
    std::cerr << "usage: " << argv[0] << " slice|volume -V baseline.png -T output_folder [-I]\n";
    return EXIT_FAILURE;
  }
  const char* display = std::getenv("DISPLAY");
  if (!display || !*display)
  {
    std::cout << "No DISPLAY: skipped (run under xvfb-run -a)\n";
    return 125;
  }

  vtkNew<vtkRenderer> renderer;
  if (!(view == "slice" ? AddSlice(renderer) : AddVolume(renderer)))
  {
    return EXIT_FAILURE;
  }
  vtkNew<vtkRenderWindow> window;
  window->SetSize(WindowWidth, WindowHeight);
  window->AddRenderer(renderer);
  vtkNew<vtkRenderWindowInteractor> interactor;
  interactor->SetRenderWindow(window);
  window->Render();

  const int result = vtkRegressionTestImage(window);
  if (result == vtkTesting::DO_INTERACTOR)
  {
    interactor->Start();
  }
  return result == vtkTesting::FAILED ? EXIT_FAILURE : EXIT_SUCCESS;
}

// C++ example: read a tracked sweep, train a Gaussian scattering field briefly, reslice an oblique
// plane through the middle of the sweep and write it as PNG.
//
//   TrainAndReslice SWEEP [CALIBRATION_XML] OUTPUT.png [ITERATIONS]
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkImageData.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkPNGWriter.h"
#include "vtkUltrasoundSequenceReader.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

int main(int argc, char** argv)
{
  if (argc < 3)
  {
    std::fprintf(stderr, "usage: %s SWEEP [CALIBRATION_XML] OUTPUT.png [ITERATIONS]\n", argv[0]);
    return 2;
  }
  const bool calibrated = argc >= 4 && std::string(argv[2]).find(".xml") != std::string::npos;
  const char* output = argv[calibrated ? 3 : 2];
  const int iterations = argc > (calibrated ? 4 : 3) ? std::atoi(argv[calibrated ? 4 : 3]) : 300;

  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(argv[1]);
  if (calibrated)
  {
    reader->SetCalibrationFileName(argv[2]);
  }
  reader->Update();
  if (*reader->GetLastErrorText())
  {
    std::fprintf(stderr, "%s\n", reader->GetLastErrorText());
    return 1;
  }

  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputConnection(reader->GetOutputPort());
  trainer->SetIterations(iterations);
  trainer->SetElevationSigma(1.0);
  trainer->Update();
  std::printf("trained %lld Gaussians in %.1f s\n", static_cast<long long>(trainer->GetNumberOfGaussians()),
    trainer->GetTrainingSeconds());

  // The oblique plane: the middle frame's plane turned 30 degrees about its depth axis (v).
  vtkImageData* frames = reader->GetOutput();
  const int middle = frames->GetDimensions()[2] / 2;
  double m[16];
  frames->GetFieldData()->GetArray("ImageToReference")->GetTuple(middle, m);
  double u[3], v[3], n[3], su = 0, sv = 0;
  for (int r = 0; r < 3; ++r)
  {
    u[r] = m[4 * r];
    v[r] = m[4 * r + 1];
    su += u[r] * u[r];
    sv += v[r] * v[r];
  }
  su = std::sqrt(su);
  sv = std::sqrt(sv);
  for (int r = 0; r < 3; ++r)
  {
    u[r] /= su;
    v[r] /= sv;
  }
  n[0] = u[1] * v[2] - u[2] * v[1];
  n[1] = u[2] * v[0] - u[0] * v[2];
  n[2] = u[0] * v[1] - u[1] * v[0];
  const double c = std::cos(M_PI / 6), s = std::sin(M_PI / 6);
  const double x[3] = { c * u[0] + s * n[0], c * u[1] + s * n[1], c * u[2] + s * n[2] };
  const double z[3] = { x[1] * v[2] - x[2] * v[1], x[2] * v[0] - x[0] * v[2], x[0] * v[1] - x[1] * v[0] };
  const int width = frames->GetDimensions()[0], height = frames->GetDimensions()[1];
  const double centre[3] = { m[0] * width / 2 + m[1] * height / 2 + m[3], m[4] * width / 2 + m[5] * height / 2 + m[7],
    m[8] * width / 2 + m[9] * height / 2 + m[11] };

  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputConnection(trainer->GetOutputPort());
  reslice->SetResliceAxesDirectionCosines(x[0], x[1], x[2], v[0], v[1], v[2], z[0], z[1], z[2]);
  reslice->SetResliceAxesOrigin(centre[0], centre[1], centre[2]);
  reslice->SetOutputSpacing(su, sv, 1);
  reslice->SetOutputOrigin(-su * width / 2, -sv * height / 2, 0);
  reslice->SetOutputExtent(0, width - 1, 0, height - 1, 0, 0);
  reslice->SetOutputScalarTypeToUnsignedChar();

  vtkNew<vtkPNGWriter> writer;
  writer->SetInputConnection(reslice->GetOutputPort());
  writer->SetFileName(output);
  writer->Write();
  std::printf("oblique slice (%d x %d) written to %s\n", width, height, output);
  return 0;
}

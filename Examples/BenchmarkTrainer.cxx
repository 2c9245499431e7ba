// Training on a real sweep with the hold-out protocol, quality against training time.
//
//   BenchmarkTrainer [SWEEP] [--minutes 1,2,5,10] [--iterations N] [--sigma MM] [--initial N]
//
// Frames with index i mod 4 == 2 are held out. Prints, for each time mark, the held-out masked PSNR,
// SSIM, NCC and speckle score (bigusImageMetrics.h), the Gaussian count and the peak memory, next to
// two classical baselines: the nearest training frame by pose and the linear blend of the two training
// frames that bracket a held-out frame in time.
#include "bigusImageMetrics.h"
#include "bigusTrainer.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace bigus;

namespace
{
double PeakMemoryMiB()
{
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
  {
    if (line.rfind("VmHWM:", 0) == 0)
    {
      return std::stod(line.substr(6)) / 1024.0;
    }
  }
  return 0;
}

struct Mean
{
  double PSNR = 0, SSIM = 0, NCC = 0, Speckle = 0;
  void Add(const ImageMetrics& m, double n)
  {
    this->PSNR += m.PSNR / n;
    this->SSIM += m.SSIM / n;
    this->NCC += m.NCC / n;
    this->Speckle += m.Speckle / n;
  }
};

void PrintRow(const char* name, const Mean& m, const std::string& extra)
{
  std::printf("%-34s %7.2f %7.4f %7.4f %8.4f  %s\n", name, m.PSNR, m.SSIM, m.NCC, m.Speckle, extra.c_str());
}
}

int main(int argc, char** argv)
{
  std::string sweep = std::string(BIGUS_EXAMPLE_DATA) + "/liver/liver_sweep.igs.mha";
  std::vector<double> marks = { 60, 120, 300, 600 };
  TrainerSettings s;
  s.Iterations = 6000;
  s.ElevationSigma = 1.0;
  for (int a = 1; a < argc; ++a)
  {
    const std::string arg = argv[a];
    if (arg == "--minutes" && a + 1 < argc)
    {
      marks.clear();
      std::stringstream list(argv[++a]);
      std::string item;
      while (std::getline(list, item, ','))
      {
        marks.push_back(60 * std::stod(item));
      }
    }
    else if (arg == "--iterations" && a + 1 < argc)
    {
      s.Iterations = std::stoi(argv[++a]);
    }
    else if (arg == "--sigma" && a + 1 < argc)
    {
      s.ElevationSigma = std::stod(argv[++a]);
    }
    else if (arg == "--initial" && a + 1 < argc)
    {
      s.InitialGaussians = std::stoll(argv[++a]);
    }
    else
    {
      sweep = arg;
    }
  }

  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(sweep.c_str());
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  if (*reader->GetLastErrorText())
  {
    std::fprintf(stderr, "%s\n", reader->GetLastErrorText());
    return 1;
  }
  vtkImageData* frames = reader->GetOutput();
  int dims[3];
  frames->GetDimensions(dims);
  TrainingData data;
  data.Width = dims[0];
  data.Height = dims[1];
  vtkDataArray* pixels = frames->GetPointData()->GetScalars();
  const double scale = pixels->GetDataType() == VTK_UNSIGNED_CHAR ? 1.0 / 255 : 1.0;
  for (vtkIdType p = 0; p < pixels->GetNumberOfTuples(); ++p)
  {
    data.Frames.push_back(static_cast<float>(pixels->GetTuple1(p) * scale));
  }
  const auto* mask = static_cast<unsigned char*>(fan->GetOutput()->GetScalarPointer());
  data.Mask.assign(mask, mask + dims[0] * dims[1]);
  std::vector<int> heldOut;
  for (int k = 0; k < dims[2]; ++k)
  {
    std::array<double, 16> m;
    frames->GetFieldData()->GetArray("ImageToReference")->GetTuple(k, m.data());
    data.Poses.push_back(m);
    (k % 4 == 2 ? heldOut : data.TrainFrames).push_back(k);
  }
  vtkDataArray* stamps = frames->GetFieldData()->GetArray("Timestamp");
  const std::size_t framePixels = std::size_t(dims[0]) * dims[1];
  std::printf("%s: %d frames of %d x %d, %zu training, %zu held out (i mod 4 == 2); sigma_E %.2f mm\n",
    sweep.c_str(), dims[2], dims[0], dims[1], data.TrainFrames.size(), heldOut.size(), s.ElevationSigma);
  std::printf("%-34s %7s %7s %7s %8s\n", "method", "PSNR", "SSIM", "NCC", "speckle");

  // Baselines.
  Mean nearest, blend;
  std::vector<float> mix(framePixels);
  for (int k : heldOut)
  {
    const float* truth = &data.Frames[framePixels * k];
    auto centre = [&](int f, int c) {
      return data.Poses[f][4 * c] * dims[0] / 2 + data.Poses[f][4 * c + 1] * dims[1] / 2 + data.Poses[f][4 * c + 3];
    };
    int best = data.TrainFrames.front();
    double bestDistance = 1e300;
    for (int t : data.TrainFrames)
    {
      const double d = std::hypot(centre(k, 0) - centre(t, 0), centre(k, 1) - centre(t, 1), centre(k, 2) - centre(t, 2));
      if (d < bestDistance)
      {
        bestDistance = d;
        best = t;
      }
    }
    nearest.Add(CompareImages(&data.Frames[framePixels * best], truth, data.Mask.data(), dims[0], dims[1]), heldOut.size());
    const int before = k - 1, after = std::min(k + 1, dims[2] - 1);
    const double t0 = stamps->GetTuple1(before), t1 = stamps->GetTuple1(after), tk = stamps->GetTuple1(k);
    const double w = t1 > t0 ? (tk - t0) / (t1 - t0) : 0.5;
    for (std::size_t p = 0; p < framePixels; ++p)
    {
      mix[p] = static_cast<float>((1 - w) * data.Frames[framePixels * before + p] + w * data.Frames[framePixels * after + p]);
    }
    blend.Add(CompareImages(mix.data(), truth, data.Mask.data(), dims[0], dims[1]), heldOut.size());
  }
  PrintRow("nearest training frame (pose)", nearest, "");
  PrintRow("blend of bracketing frames (time)", blend, "");

  Trainer trainer(data, s);
  std::string error;
  if (!trainer.Initialize(&error))
  {
    std::fprintf(stderr, "%s\n", error.c_str());
    return 1;
  }
  double trained = 0;
  for (double mark : marks)
  {
    const auto start = std::chrono::steady_clock::now();
    const double slice = mark - trained;
    trainer.Run(nullptr,
      [&]() { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= slice; },
      &error);
    trained = mark;
    Mean bigus;
    double renderSeconds = 0;
    bigus.Add(trainer.Evaluate(heldOut, &renderSeconds), 1);
    char name[64], extra[200];
    std::snprintf(name, sizeof(name), "BIGUS after %.0f s", mark);
    std::snprintf(extra, sizeof(extra), "%lld Gaussians, %d steps, %.0f ms/frame render, peak memory %.0f MiB",
      static_cast<long long>(trainer.GetField().Count()), trainer.GetIteration(), 1e3 * renderSeconds, PeakMemoryMiB());
    PrintRow(name, bigus, extra);
    std::fflush(stdout);
    if (trainer.GetIteration() >= s.Iterations)
    {
      std::printf("(all %d iterations done before this mark)\n", s.Iterations);
      break;
    }
  }
  std::printf("growth: %s\n", trainer.GetReport().GrowthStopReason.c_str());
  return 0;
}

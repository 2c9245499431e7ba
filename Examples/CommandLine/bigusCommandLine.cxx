// What the commands of `bigus` share: failing with a message, reading sweeps, fields and masks, writing images.
#include "bigusCommandLine.h"
#include "bigusPlot.h"
#include "bigusTrainingEngine.h"
#include "vtkCallbackCommand.h"
#include "vtkCommand.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkMetaImageReader.h"
#include "vtkMetaImageWriter.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkXMLImageDataWriter.h"
#include "vtkXMLPolyDataReader.h"
#include "vtkXMLPolyDataWriter.h"

#include <CLI/CLI.hpp>
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on
#include <vtksys/SystemTools.hxx>
#include <algorithm>
#include <cstdlib>
#include <mpi.h>
#include <thread>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

namespace bigus::cli
{
int Fail(const std::string& what)
{
  std::fprintf(stderr, "bigus: %s\n", what.c_str());
  return 1;
}

FilterError::FilterError()
{
  this->Callback->SetClientData(&this->Text);
  this->Callback->SetCallback([](vtkObject*, unsigned long, void* client, void* data) {
    std::string text = static_cast<const char*>(data);
    const std::size_t start = text.rfind("): ");
    text = start == std::string::npos ? text : text.substr(start + 3);
    text.erase(std::remove(text.begin(), text.end(), '\n'), text.end());
    *static_cast<std::string*>(client) = text;
  });
}

void FilterError::Watch(vtkObject* object)
{
  object->AddObserver(vtkCommand::ErrorEvent, this->Callback);
}

bool EndsWith(const std::string& s, const std::string& suffix)
{
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

CLI::Validator FiniteRange(double lowest, double highest, bool positive)
{
  const std::string range = highest >= 1e300
    ? vtkfmt::sprintf("%s %g", positive ? "above" : "at least", lowest)
    : vtkfmt::sprintf("%s %g and at most %g", positive ? "above" : "at least", lowest, highest);
  return CLI::Validator(
    [=](std::string& text) -> std::string {
      double value = 0;
      std::size_t used = 0;
      try
      {
        value = std::stod(text, &used);
      }
      catch (const std::out_of_range&)
      {
        return "'" + text + "' is not a finite number";
      }
      catch (const std::exception&)
      {
        return "'" + text + "' is not a number";
      }
      if (used != text.size() || !std::isfinite(value))
      {
        return "'" + text + "' is not a finite number";
      }
      if (value < lowest || value > highest || (positive && value == lowest))
      {
        return "'" + text + "' is not " + range;
      }
      return std::string();
    },
    "NUMBER " + range);
}

CLI::Validator FiniteNonNegative(double highest)
{
  return FiniteRange(0, highest);
}

CLI::Validator FinitePositive(double highest)
{
  return FiniteRange(0, highest, true);
}

vtkSmartPointer<vtkUltrasoundSequenceReader> ReadSweep(const SweepOptions& o)
{
  auto reader = vtkSmartPointer<vtkUltrasoundSequenceReader>::New();
  reader->SetFileName(o.Sweep.c_str());
  if (!o.Calibration.empty())
  {
    reader->SetCalibrationFileName(o.Calibration.c_str());
  }
  if (!o.Chain.empty())
  {
    reader->SetTransformChain(o.Chain.c_str());
  }
  if (o.FrameRange.size() == 2)
  {
    reader->SetFrameRange(o.FrameRange[0], o.FrameRange[1]);
  }
  reader->Update();
  if (*reader->GetLastErrorText())
  {
    Fail(reader->GetLastErrorText());
    return nullptr;
  }
  return reader;
}

vtkSmartPointer<vtkImageData> WithOwnFieldData(vtkImageData* sweep)
{
  auto copy = vtkSmartPointer<vtkImageData>::New();
  copy->ShallowCopy(sweep);
  vtkNew<vtkFieldData> fields;
  fields->DeepCopy(sweep->GetFieldData());
  copy->SetFieldData(fields);
  return copy;
}

namespace
{
/// True after a message when @p file is there but is not a regular file (a folder, pipe or device: opening a pipe
/// would block); @p kind says what the file should be. A missing file is left to the caller's open.
bool RefuseIrregularFile(const std::string& file, const std::string& kind)
{
  std::error_code status;
  if (!std::filesystem::exists(file, status) || std::filesystem::is_regular_file(file, status))
  {
    return false;
  }
  Fail(file + ": not a regular file (a folder, pipe or device); " + kind);
  return true;
}
}

vtkSmartPointer<vtkPolyData> ReadField(const std::string& file)
{
  if (RefuseIrregularFile(file, "a Gaussian field is a .vtp file"))
  {
    return nullptr;
  }
  std::ifstream probe(file);
  if (!probe)
  {
    Fail(file + ": cannot open the field file");
    return nullptr;
  }
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(file.c_str());
  // The counts the file claims, against what it holds and what this machine has, before VTK allocates for them.
  FilterError error;
  error.Watch(reader);
  reader->UpdateInformation();
  if (!error.Text.empty())
  {
    Fail(file + ": not a Gaussian field (.vtp): " + error.Text);
    return nullptr;
  }
  reader->SetupUpdateExtent(0, 1, 0);
  const double points = static_cast<double>(reader->GetNumberOfPoints());
  const double cells = static_cast<double>(reader->GetNumberOfCells());
  // Per Gaussian at least 44 bytes (position, Scale, Rotation, Reflectivity as floats), 16 per vertex cell; zlib
  // packs at most 1032:1; in memory the reader's copy, the command's and the renderer's field.
  const double stored = 44 * points + 16 * cells;
  std::error_code status;
  const double fileBytes = static_cast<double>(std::filesystem::file_size(file, status));
  const double physical = PhysicalMemoryBytes();
  if (points < 0 || cells < 0 || stored > 1032 * fileBytes)
  {
    Fail(vtkfmt::sprintf("%s: claims %.0f Gaussians and %.0f cells, at least %.0f bytes of data even compressed, and "
                         "the file holds %.0f bytes",
      file, points, cells, stored / 1032, fileBytes));
    return nullptr;
  }
  if (physical > 0 && 3 * stored > physical)
  {
    Fail(vtkfmt::sprintf("%s: its %.0f Gaussians need %.0f MB to read and this machine has %.0f MB", file, points,
      3 * stored / 1e6, physical / 1e6));
    return nullptr;
  }
  reader->Update();
  vtkPolyData* field = reader->GetOutput();
  if (!field || field->GetNumberOfPoints() == 0 || !field->GetPointData()->GetArray("Scale"))
  {
    Fail(file + ": not a Gaussian field (.vtp with point data Scale, Rotation, Reflectivity)");
    return nullptr;
  }
  auto copy = vtkSmartPointer<vtkPolyData>::New();
  copy->DeepCopy(field);
  return copy;
}

bool FrameIsValid(vtkImageData* sweep, int k)
{
  vtkDataArray* valid = sweep->GetFieldData()->GetArray("FrameValid");
  return !valid || valid->GetNumberOfTuples() != sweep->GetDimensions()[2] || valid->GetTuple1(k) != 0;
}

std::vector<int> ChooseFrames(int count, int every, int offset, const std::vector<int>& list)
{
  std::vector<int> frames;
  for (int k = 0; k < count; ++k)
  {
    if (!list.empty() ? std::find(list.begin(), list.end(), k) != list.end() : (every <= 0 || k % every == offset))
    {
      frames.push_back(k);
    }
  }
  return frames;
}

vtkSmartPointer<vtkImageData> ReadMask(const std::string& file, const int dims[3])
{
  if (RefuseIrregularFile(file, "a mask is a .mha or .mhd file"))
  {
    return nullptr;
  }
  std::ifstream probe(file);
  if (!probe)
  {
    Fail(file + ": cannot open the mask");
    return nullptr;
  }
  vtkNew<vtkMetaImageReader> reader;
  reader->SetFileName(file.c_str());
  // The size the header claims, before VTK allocates it: within this machine's memory and, for pixels stored
  // uncompressed in the file itself (ElementDataFile = LOCAL), within the file (a truncated mask is refused).
  reader->UpdateInformation();
  const int* extent = reader->GetDataExtent();
  const double needed = double(extent[1] - extent[0] + 1) * double(extent[3] - extent[2] + 1) *
    double(extent[5] - extent[4] + 1) * std::max(1, reader->GetNumberOfScalarComponents()) *
    std::max(1, vtkDataArray::GetDataTypeSize(reader->GetDataScalarType()));
  std::string header(65536, '\0');
  probe.read(&header[0], static_cast<std::streamsize>(header.size()));
  header.resize(static_cast<std::size_t>(probe.gcount()));
  const std::size_t dataFile = header.find("ElementDataFile");
  const std::size_t headerBytes = dataFile == std::string::npos ? 0 : header.find('\n', dataFile) + 1;
  header.erase(
    std::remove_if(header.begin(), header.end(), [](char c) { return c == ' ' || c == '\t'; }), header.end());
  std::transform(header.begin(), header.end(), header.begin(), [](unsigned char c) { return std::tolower(c); });
  std::error_code status;
  const double fileBytes = static_cast<double>(std::filesystem::file_size(file, status)) - double(headerBytes);
  const bool localRaw = header.find("elementdatafile=local") != std::string::npos &&
    header.find("compresseddata=true") == std::string::npos && header.find("compresseddata=1") == std::string::npos;
  const double physical = PhysicalMemoryBytes();
  const bool truncated = localRaw && fileBytes < needed;
  if (truncated || (physical > 0 && 2 * needed > physical))
  {
    Fail(vtkfmt::sprintf("%s: its DimSize %d x %d x %d needs %.0f bytes of pixel data, and %s holds %.0f", file,
      extent[1] - extent[0] + 1, extent[3] - extent[2] + 1, extent[5] - extent[4] + 1, needed,
      truncated ? "the file" : "this machine's memory (half of it)", truncated ? fileBytes : physical / 2));
    return nullptr;
  }
  reader->Update();
  vtkImageData* mask = reader->GetOutput();
  int size[3] = { 0, 0, 0 };
  mask->GetDimensions(size);
  if (!mask->GetPointData()->GetScalars() || mask->GetNumberOfScalarComponents() != 1 || size[0] != dims[0] ||
    size[1] != dims[1] || (size[2] != 1 && size[2] != dims[2]))
  {
    Fail(file + ": the mask must be one-component " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) +
      " x 1 or x " + std::to_string(dims[2]) + " (one per frame), not " + std::to_string(size[0]) + " x " +
      std::to_string(size[1]) + " x " + std::to_string(size[2]));
    return nullptr;
  }
  auto copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(mask);
  return copy;
}

void AddSweepOptions(CLI::App* command, SweepOptions& o, const char* what)
{
  command->add_option("--calibration", o.Calibration, "PLUS device-set configuration XML (ImageToProbe)")
    ->check(CLI::ExistingFile);
  command->add_option("--transform", o.Chain,
    std::string("Transform chain for ImageToReference of the ") + what +
      ", e.g. \"inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe\"");
}

bool LaunchedByMpi()
{
  for (const char* variable : { "OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK" })
  {
    if (std::getenv(variable))
    {
      return true;
    }
  }
  return false;
}

int ThreadsPerRank()
{
  MPI_Comm node;
  int local = 1;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
  MPI_Comm_size(node, &local);
  MPI_Comm_free(&node);
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()) / local);
}

int CheckOutputs(const std::vector<std::string>& outputs, const std::vector<std::string>& inputs)
{
  using vtksys::SystemTools;
  for (std::size_t k = 0; k < outputs.size(); ++k)
  {
    const std::string& output = outputs[k];
    if (output.empty())
    {
      continue;
    }
    const std::string full = SystemTools::CollapseFullPath(output);
    const bool exists = SystemTools::FileExists(output);
    if (exists && SystemTools::FileIsDirectory(output))
    {
      return Fail(output + ": is a folder, not a file to write");
    }
    for (const std::string& input : inputs)
    {
      if (!input.empty() && exists && SystemTools::SameFile(output, input))
      {
        return Fail(output + ": is also an input (" + input + "); it would be replaced. Write to another file");
      }
    }
    for (std::size_t m = 0; m < k; ++m)
    {
      if (!outputs[m].empty() &&
        (SystemTools::CollapseFullPath(outputs[m]) == full ||
          (exists && SystemTools::FileExists(outputs[m]) && SystemTools::SameFile(output, outputs[m]))))
      {
        return Fail(output + ": is named for two outputs");
      }
    }
    const std::string folder = SystemTools::GetFilenamePath(full);
    if (!SystemTools::FileIsDirectory(folder))
    {
      return Fail(output + ": the folder " + folder + " does not exist");
    }
    if (!SystemTools::TestFileAccess(folder, vtksys::TEST_FILE_WRITE))
    {
      return Fail(output + ": the folder " + folder + " is not writable");
    }
  }
  return 0;
}

bool WriteText(const std::string& path, const std::string& text)
{
  const std::string temporary = TemporaryName(path);
  std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out)
  {
    std::remove(temporary.c_str());
    return false;
  }
  return Publish(temporary, path);
}

namespace
{
/// @p writer's XML, written to its output string, then to @p path by WriteText: a full disk is found before the
/// rename (VTK's XML writers do not check the close).
bool WriteXml(vtkXMLWriterBase* writer, const std::string& path)
{
  writer->WriteToOutputStringOn();
  return writer->Write() && WriteText(path, writer->GetOutputString());
}

/// Whether the compressed MetaImage @p header (as vtkMetaImageWriter writes it) holds every byte of its data: the
/// CompressedDataSize its header states, after the header (ElementDataFile LOCAL) or in its data file, whose name
/// (relative to the header's folder) goes to @p dataFile. VTK's writer does not report a write that failed.
bool MetaImageComplete(const std::string& header, std::string& dataFile)
{
  std::ifstream in(header, std::ios::binary);
  std::string line;
  double compressedBytes = -1;
  dataFile.clear();
  while (dataFile.empty() && std::getline(in, line))
  {
    const std::size_t equals = line.find('=');
    auto trim = [](const std::string& text) {
      const std::size_t first = text.find_first_not_of(" \t\r"), last = text.find_last_not_of(" \t\r");
      return first == std::string::npos ? std::string() : text.substr(first, last - first + 1);
    };
    const std::string key = trim(line.substr(0, equals));
    const std::string value = equals == std::string::npos ? std::string() : trim(line.substr(equals + 1));
    compressedBytes = key == "CompressedDataSize" ? std::atof(value.c_str()) : compressedBytes;
    dataFile = key == "ElementDataFile" ? value : dataFile;
  }
  if (!in || compressedBytes < 0 || dataFile.empty())
  {
    return false;
  }
  const std::string data = dataFile == "LOCAL" ? header : vtksys::SystemTools::GetFilenamePath(header) + "/" + dataFile;
  const double offset = dataFile == "LOCAL" ? double(in.tellg()) : 0.0;
  std::error_code status;
  const double bytes = double(std::filesystem::file_size(data, status));
  return !status && bytes - offset == compressedBytes;
}
}

int WriteField(vtkPolyData* field, const std::string& path)
{
  vtkNew<vtkXMLPolyDataWriter> writer;
  writer->SetInputData(field);
  writer->SetDataModeToAppended();
  return WriteXml(writer, path) ? 0 : Fail(path + ": cannot write the field");
}

int WriteImage(vtkImageData* image, const std::string& path)
{
  if (EndsWith(path, ".png"))
  {
    int dims[3];
    image->GetDimensions(dims);
    vtkDataArray* values = image->GetPointData()->GetScalars();
    cv::Mat png(dims[1], dims[0], CV_8U);
    for (int j = 0; j < dims[1]; ++j)
    {
      for (int i = 0; i < dims[0]; ++i)
      {
        const double v = values->GetTuple1(vtkIdType(j) * dims[0] + i);
        png.at<unsigned char>(j, i) = static_cast<unsigned char>(
          std::lround(std::min(255.0, std::max(0.0, values->GetDataType() == VTK_FLOAT ? 255 * v : v))));
      }
    }
    return WritePng(png, path) ? 0 : Fail(path + ": cannot write the image");
  }
  if (EndsWith(path, ".vti"))
  {
    vtkNew<vtkXMLImageDataWriter> writer;
    writer->SetInputData(image);
    return WriteXml(writer, path) ? 0 : Fail(path + ": cannot write the image");
  }
  if (!EndsWith(path, ".mha") && !EndsWith(path, ".mhd"))
  {
    return Fail(path + ": unknown image format (use .png, .mha or .vti)");
  }
  // Written in a staging folder beside the output under the output's own names (a .mhd's header names its data file
  // as it will be called), checked complete, then each file renamed into place.
  using vtksys::SystemTools;
  const std::string staging = TemporaryName(path);
  const std::string name = SystemTools::GetFilenameName(path);
  std::string folder = SystemTools::GetFilenamePath(path);
  folder = folder.empty() ? "." : folder;
  std::string dataFile;
  std::error_code status;
  bool ok = std::filesystem::create_directory(staging, status) && !status;
  if (ok)
  {
    vtkNew<vtkMetaImageWriter> writer;
    writer->SetInputData(image);
    writer->SetFileName((staging + "/" + name).c_str());
    writer->SetCompression(true);
    writer->Write();
    ok = writer->GetErrorCode() == 0 && MetaImageComplete(staging + "/" + name, dataFile) &&
      (dataFile == "LOCAL" || Publish(staging + "/" + dataFile, folder + "/" + dataFile)) &&
      Publish(staging + "/" + name, path);
  }
  std::filesystem::remove_all(staging, status);
  return ok ? 0 : Fail(path + ": cannot write the image (folder not writable, or disk full)");
}
} // namespace bigus::cli

/**
 * @file bigusCommandLine.h
 * @brief What the commands of the `bigus` program share (one file per command beside this one, each with
 *        an Add...Command that declares its options on a CLI11 app and a Run... that does the work).
 *
 * Exit codes of every command: 0 success, 1 a bad file or a failed step (one line on stderr), 2 bad
 * arguments. Outputs are written under a temporary name and renamed (bigus::Publish): an existing file is
 * never left half-written.
 */
#ifndef bigusCommandLine_h
#define bigusCommandLine_h

#include "bigusReplaceFile.h"

#include "vtkCallbackCommand.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkSmartPointer.h"
#include "vtkUltrasoundSequenceReader.h"

#include <functional>
#include <string>
#include <vector>

namespace CLI
{
class App;
class Validator;
}
class vtkObject;

namespace bigus::cli
{
/// A subcommand of `bigus` and what runs when it was the one parsed (returns the exit code).
struct Command
{
  CLI::App* App = nullptr;
  std::function<int()> Run;
};

Command AddInfoCommand(CLI::App& app);
Command AddTrainCommand(CLI::App& app);
/// Whether `bigus train` takes SIGINT and SIGTERM as a request to stop with a checkpoint (true, the default) or
/// leaves them to end the process (`bigus batch`: its jobs end with the process, and a rerun resumes the queue).
void SetGracefulStop(bool graceful);
Command AddRenderCommand(CLI::App& app);
Command AddEvaluateCommand(CLI::App& app);
Command AddSweepCommand(CLI::App& app);
Command AddFillGapsCommand(CLI::App& app);
/// `bigus merge`: merge neighbouring Gaussians of a trained field (bigusMergeCommand.cxx).
Command AddMergeCommand(CLI::App& app);
/// `bigus batch`: the jobs of a manifest, in one process or on MPI ranks (bigusBatchCommand.cxx).
Command AddBatchCommand(CLI::App& app);
/// @p sourceDirectory: where `bigus benchmark` finds Examples/Data and Testing/Data unless --data says.
Command AddBenchmarkCommand(CLI::App& app, const std::string& sourceDirectory);

/**
 * A number option's check: finite and within [@p lowest, @p highest] (CLI11's NonNegativeNumber, PositiveNumber and
 * Range let NaN and infinity through, since every comparison with NaN is false). @p positive: @p lowest excluded.
 * A value outside is refused when the command line is parsed, naming the option, the value and the range.
 */
CLI::Validator FiniteRange(double lowest, double highest, bool positive = false);
/// FiniteRange(0, highest): finite and non-negative.
CLI::Validator FiniteNonNegative(double highest = 1e300);
/// FiniteRange(0, highest, true): finite and positive.
CLI::Validator FinitePositive(double highest = 1e300);

/// Prints "bigus: @p what" on stderr; returns 1 (the exit code of a bad file or a failed step).
int Fail(const std::string& what);

/**
 * The last error a watched VTK object reported, on one line. VTK's output window is silenced (main),
 * so the command line reports a filter's own message ("ERROR: In <file>, line <n>\n<class>
 * (<address>): <message>\n\n" keeps <message>) instead of its own guess.
 */
class FilterError
{
public:
  FilterError();
  FilterError(const FilterError&) = delete;
  FilterError& operator=(const FilterError&) = delete;
  void Watch(vtkObject* object);
  /// The message, or @p fallback when none was reported.
  std::string Or(const std::string& fallback) const { return this->Text.empty() ? fallback : this->Text; }
  std::string Text;

private:
  vtkNew<vtkCallbackCommand> Callback;
};

bool EndsWith(const std::string& s, const std::string& suffix);

/// A sweep on the command line: the sequence metafile, its calibration and transform chain, a frame range.
struct SweepOptions
{
  std::string Sweep, Calibration, Chain;
  std::vector<int> FrameRange; ///< empty, or first and last frame
};

/// --calibration and --transform for the sweep @p what names ("sweep", "pose sweep").
void AddSweepOptions(CLI::App* command, SweepOptions& o, const char* what);

/// Reads a sweep; on failure prints the reader's message and returns null.
vtkSmartPointer<vtkUltrasoundSequenceReader> ReadSweep(const SweepOptions& o);

/// Reads a Gaussian field (.vtp with point data Scale, Rotation, Reflectivity); null after a message.
vtkSmartPointer<vtkPolyData> ReadField(const std::string& file);

/**
 * Before any work: each of @p outputs (empty ones skipped) is refused when it is one of @p inputs (the same file,
 * links resolved: vtksys::SystemTools::SameFile) or another of @p outputs, when it is a folder, or when its folder
 * is missing or not writable. 0, or 1 after a message naming the output and what is wrong, so that nothing the
 * user had is replaced and no run is lost to an output it cannot write.
 */
int CheckOutputs(const std::vector<std::string>& outputs, const std::vector<std::string>& inputs);

/// Writes @p text to @p path through a temporary file in its folder, every write and the close checked, then renamed
/// over @p path (Publish); false when any step failed (the temporary removed, an existing @p path untouched).
bool WriteText(const std::string& path, const std::string& text);

/// Writes @p field (.vtp, appended data) under a temporary name, then renames it to @p path (Publish); 0, or 1
/// after a message (the temporary file removed, an existing @p path untouched).
int WriteField(vtkPolyData* field, const std::string& path);

/// A copy of @p sweep that shares its frames and owns its field data, so that its ImageToReference can be
/// changed (refined poses) without touching @p sweep.
vtkSmartPointer<vtkImageData> WithOwnFieldData(vtkImageData* sweep);

/**
 * Whether frame @p k of a sweep may be used: its FrameValid value is non-zero, or the sweep has no
 * FrameValid of one value per frame (every frame valid), as vtkGaussianFieldTrainer and
 * vtkUltrasoundVolumeCompounder read it.
 */
bool FrameIsValid(vtkImageData* sweep, int k);

/// Frames with index k mod every == offset (every > 0), or the explicit list, or all.
std::vector<int> ChooseFrames(int count, int every, int offset, const std::vector<int>& list);

/// Reads a fan mask (.mha/.mhd, W x H x 1, or W x H x N: one per frame) for a W x H x N sweep;
/// on failure prints what is wrong and returns null.
vtkSmartPointer<vtkImageData> ReadMask(const std::string& file, const int dims[3]);

/// True when this process was started by mpirun / mpiexec (Open MPI, MPICH or PMIx launchers).
bool LaunchedByMpi();
/// With MPI initialised: this machine's cores divided among the ranks on it (at least 1), so that ranks that
/// share a machine do not oversubscribe its cores.
int ThreadsPerRank();

/// Writes an image: .png (8-bit, rows flipped so that row 0 is the top), .mha (MetaImage), .vti.
/// Returns the exit code (1 after a message).
int WriteImage(vtkImageData* image, const std::string& path);

} // namespace bigus::cli

#endif

// `bigus batch` (bigusBatchCommand.cxx): the jobs of its manifest, read and checked before any runs
// (bigusBatchManifest.cxx), and the in-process run of their `bigus train` and `bigus evaluate`.
#ifndef bigusBatchManifest_h
#define bigusBatchManifest_h

#include <string>
#include <vector>

namespace bigus::cli
{
/// One job of the manifest: the arguments of its `bigus train` and `bigus evaluate`, resolved and checked.
struct BatchJob
{
  std::string Name, Output; ///< Output: the job's folder (field.vtp, metrics.json, log.txt, job.json)
  int Line = 0;             ///< line of the job in the manifest
  std::vector<std::string> TrainArguments, EvaluateArguments;
  /// --frames jobs: the training frames, whose complement in the sweep is scored (found when the job runs).
  std::vector<int> TrainingFrames;
};

/// Runs a `bigus` command on @p arguments (as on the command line after "bigus"); @p dryRun parses only.
/// Throws CLI::ParseError for bad arguments.
int RunCommand(const std::vector<std::string>& arguments, bool dryRun);

/// The manifest's jobs, checked before any runs; false with @p error naming the line that is wrong.
bool ReadManifest(const std::string& file, std::vector<BatchJob>& jobs, std::string& error);
}

#endif

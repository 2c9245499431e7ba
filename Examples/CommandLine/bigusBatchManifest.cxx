// `bigus batch`: reading and checking its manifest (bigusBatchManifest.h); errors name the manifest's line.
#include "bigusBatchManifest.h"

#include "bigusCommandLine.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace bigus::cli
{
namespace
{
namespace fs = std::filesystem;
using json = nlohmann::json;

/// Where the manifest's jobs and keys are (1-based lines): JSON parsers give values, not positions.
struct ManifestLines
{
  std::vector<int> Jobs;
  std::vector<std::map<std::string, int>> JobKeys;
  std::map<std::string, int> DefaultKeys;
  /// The first key given twice in one object ("\"key\" appears twice, lines A and B"; JSON parsers keep the
  /// last), empty when none is.
  std::string Duplicate;
};

ManifestLines LocateLines(const std::string& text)
{
  ManifestLines lines;
  std::vector<std::string> openedBy; // per open container: the top-level key whose value it is
  std::map<std::string, int> topLevel;
  std::string key;
  int line = 1;
  for (std::size_t i = 0; i < text.size(); ++i)
  {
    const char c = text[i];
    if (c == '\n')
    {
      ++line;
    }
    else if (c == '"')
    {
      const std::size_t start = ++i;
      for (; i < text.size() && text[i] != '"'; ++i)
      {
        i += text[i] == '\\';
      }
      const std::size_t next = text.find_first_not_of(" \t\r\n", i + 1);
      if (next != std::string::npos && text[next] == ':')
      {
        key = text.substr(start, i - start);
        const std::size_t depth = openedBy.size();
        std::map<std::string, int>* keys = depth == 3 && openedBy[1] == "jobs" && !lines.JobKeys.empty()
          ? &lines.JobKeys.back()
          : (depth == 2 && openedBy[1] == "defaults" ? &lines.DefaultKeys : (depth == 1 ? &topLevel : nullptr));
        if (keys)
        {
          const auto seen = keys->emplace(key, line);
          if (!seen.second && lines.Duplicate.empty())
          {
            lines.Duplicate = "\"" + key + "\" appears twice in one object (lines " +
              std::to_string(seen.first->second) + " and " + std::to_string(line) + "); give it once";
          }
        }
      }
    }
    else if (c == '{' || c == '[')
    {
      openedBy.push_back(openedBy.size() == 1 ? key : (openedBy.size() > 1 ? openedBy[1] : ""));
      if (openedBy.size() == 3 && openedBy[1] == "jobs" && c == '{')
      {
        lines.Jobs.push_back(line);
        lines.JobKeys.emplace_back();
      }
      key.clear();
    }
    else if ((c == '}' || c == ']') && !openedBy.empty())
    {
      openedBy.pop_back();
    }
  }
  return lines;
}

/// The options of `bigus train` that are paths, resolved against the manifest's folder ("sweep" too) or the
/// job's output folder; "resume" is refused (a rerun of the batch resumes), and so is "distributed" (a job trains
/// on one rank), "output" is the job's folder.
bool IsInputPath(const std::string& key)
{
  return key == "sweep" || key == "calibration" || key == "mask";
}
bool IsOutputPath(const std::string& key)
{
  return key == "checkpoint" || key == "refined-poses";
}

/// A manifest value as `bigus train` arguments (a list: one per element): paths resolved (IsInputPath against
/// @p folder, IsOutputPath against the job's @p output), numbers as written, a flag's true / false. False when
/// the value is of no such kind.
bool OptionTexts(const std::string& key, const json& value, const fs::path& folder, const fs::path& output,
  std::vector<std::string>& texts)
{
  for (const json& v : value.is_array() ? value.get<std::vector<json>>() : std::vector<json>{ value })
  {
    if (v.is_string())
    {
      const std::string s = v.get<std::string>();
      texts.push_back(IsInputPath(key) ? (folder / s).lexically_normal().string()
          : IsOutputPath(key)          ? (output / s).lexically_normal().string()
                                       : s);
    }
    else if (v.is_number_integer())
    {
      texts.push_back(std::to_string(v.get<long long>()));
    }
    else if (v.is_number())
    {
      texts.push_back(v.dump());
    }
    else if (v.is_boolean() && !value.is_array())
    {
      texts.push_back(v.get<bool>() ? "true" : "false");
    }
    else
    {
      return false;
    }
  }
  return true;
}

/**
 * The arguments of a job's `bigus train` and `bigus evaluate` from its @p settings (defaults merged; job.Output
 * set), checked by parsing them with @p train's options. Returns "" or what is wrong, as "key<TAB>message" when
 * a key is to blame.
 */
std::string ReadJob(const json& settings, const fs::path& folder, const CLI::App& train, BatchJob& job)
{
  std::vector<std::string> sweeps, arguments = { "train" };
  int holdOutSweep = -1;
  std::string holdOutEvery, holdOutOffset = "0";
  std::vector<std::string> shared; // evaluate's options from the job's: the backend
  std::map<std::string, std::vector<std::string>>
    perSweep; // calibration, mask (one for all or one per sweep), transform
  for (const auto& [key, value] : settings.items())
  {
    if (key == "output" || key == "name")
    {
      continue;
    }
    if (key == "resume")
    {
      return key + "\tnot a batch option: rerunning the batch resumes it (completed jobs are skipped)";
    }
    if (key == "distributed")
    {
      return key +
        "\tnot a batch option: under mpirun the batch shares its jobs between the ranks, each job "
        "trained by one of them";
    }
    if (key != "sweep" && !train.get_option_no_throw("--" + key))
    {
      return key +
        "\tunknown option (neither a batch key, \"sweep\", \"output\", \"name\", nor an option of bigus "
        "train: bigus train --help)";
    }
    std::vector<std::string> texts;
    if (!OptionTexts(key, value, folder, job.Output, texts) || texts.empty())
    {
      return key + "\texpects a string, a number, true / false, or a non-empty list of strings or numbers";
    }
    if (key == "sweep")
    {
      sweeps = texts;
      continue;
    }
    holdOutSweep = key == "holdout-sweep" ? std::atoi(texts.front().c_str()) : holdOutSweep;
    holdOutEvery = key == "holdout-every" ? texts.front() : holdOutEvery;
    holdOutOffset = key == "holdout-offset" ? texts.front() : holdOutOffset;
    if (key == "backend")
    {
      shared = { "--backend", texts.front() };
    }
    if (key == "calibration" || key == "mask" || key == "transform")
    {
      perSweep[key] = texts;
    }
    for (const std::string& t : key == "frames" ? texts : std::vector<std::string>())
    {
      job.TrainingFrames.push_back(std::atoi(t.c_str()));
    }
    for (const std::string& t : texts)
    {
      if (!value.is_boolean())
      {
        arguments.insert(arguments.end(), { "--" + key, t });
      }
      else if (value.get<bool>())
      {
        arguments.push_back("--" + key);
      }
    }
  }
  const std::string field = (fs::path(job.Output) / "field.vtp").string();
  arguments.insert(arguments.begin() + 1, sweeps.begin(), sweeps.end());
  arguments.insert(arguments.end(), { "-o", field });
  try
  {
    RunCommand(arguments, true);
  }
  catch (const CLI::ParseError& e)
  {
    std::string what = e.what();
    what.erase(std::remove(what.begin(), what.end(), '\n'), what.end());
    return what;
  }
  // What is scored: the held-out sweep, or the one sweep's frames that were held out.
  if (holdOutSweep < 0 && sweeps.size() > 1)
  {
    return "sweep\ta job of several sweeps is scored on one left out: give \"holdout-sweep\"";
  }
  if (holdOutSweep < 0 && holdOutEvery.empty() && job.TrainingFrames.empty())
  {
    return "no held-out frames to score: give \"holdout-every\" (and \"holdout-offset\"), \"frames\" or "
           "\"holdout-sweep\"";
  }
  const std::size_t scored = std::max(0, holdOutSweep);
  if (scored >= sweeps.size())
  {
    return "holdout-sweep\tthere is no sweep " + std::to_string(scored) + " (the job has " +
      std::to_string(sweeps.size()) + ")";
  }
  for (const auto& [key, files] : perSweep)
  {
    if (files.size() != 1 && files.size() != sweeps.size())
    {
      return key + "\t" + std::to_string(files.size()) + " files for " + std::to_string(sweeps.size()) +
        " sweeps: give one for every sweep, or one per sweep in their order";
    }
  }
  job.TrainArguments = arguments;
  job.EvaluateArguments = { "evaluate", field, sweeps[scored] };
  for (const auto& [key, files] : perSweep)
  {
    job.EvaluateArguments.insert(job.EvaluateArguments.end(), { "--" + key, files[files.size() == 1 ? 0 : scored] });
  }
  if (holdOutSweep < 0 && !holdOutEvery.empty())
  {
    job.EvaluateArguments.insert(
      job.EvaluateArguments.end(), { "--holdout-every", holdOutEvery, "--holdout-offset", holdOutOffset });
  }
  job.EvaluateArguments.insert(job.EvaluateArguments.end(), shared.begin(), shared.end());
  job.EvaluateArguments.insert(job.EvaluateArguments.end(), { "--report", job.Output });
  return "";
}
}

int RunCommand(const std::vector<std::string>& arguments, bool dryRun)
{
  CLI::App app;
  app.require_subcommand(1);
  const Command train = AddTrainCommand(app), evaluate = AddEvaluateCommand(app);
  std::vector<std::string> reversed(arguments.rbegin(), arguments.rend());
  app.parse(reversed);
  if (dryRun)
  {
    return 0;
  }
  return train.App->parsed() ? train.Run() : evaluate.Run();
}

bool ReadManifest(const std::string& file, std::vector<BatchJob>& jobs, std::string& error)
{
  std::ifstream in(file, std::ios::binary);
  if (!in)
  {
    error = file + ": cannot open the manifest";
    return false;
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  json manifest;
  try
  {
    manifest = json::parse(text);
  }
  catch (const json::parse_error& e)
  {
    const std::size_t end = std::min<std::size_t>(e.byte, text.size());
    const long line = 1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(end), '\n');
    error = file + ", line " + std::to_string(line) + ": not JSON (" + e.what() + ")";
    return false;
  }
  if (!manifest.is_object() || !manifest.contains("jobs") || !manifest["jobs"].is_array() || manifest["jobs"].empty())
  {
    error = file +
      ": a manifest is an object with \"jobs\": [ {\"sweep\": ..., \"output\": ...}, ... ] and "
      "optionally \"defaults\": { ... }";
    return false;
  }
  for (const auto& [key, value] : manifest.items())
  {
    if (key != "jobs" && key != "defaults")
    {
      error = file + ": unknown key \"" + key + "\" (a manifest has \"jobs\" and \"defaults\")";
      return false;
    }
  }
  const json defaults = manifest.value("defaults", json::object());
  const ManifestLines lines = LocateLines(text);
  if (!lines.Duplicate.empty())
  {
    error = file + ": " + lines.Duplicate;
    return false;
  }
  if (!defaults.is_object() || lines.Jobs.size() != manifest["jobs"].size())
  {
    error = file + ": \"defaults\" must be an object and every entry of \"jobs\" an object";
    return false;
  }
  const fs::path folder = fs::absolute(fs::path(file)).parent_path();
  std::map<std::string, std::size_t> outputs; // canonical output folder -> job
  std::map<std::string, std::size_t> names;   // job name -> job
  // The options bigus train declares, to tell an unknown key from a misspelt one before anything runs.
  CLI::App scratch;
  const CLI::App* train = AddTrainCommand(scratch).App;
  for (std::size_t j = 0; j < manifest["jobs"].size(); ++j)
  {
    BatchJob job;
    job.Line = lines.Jobs[j];
    json settings = defaults;
    settings.update(manifest["jobs"][j]);
    auto where = [&](const std::string& key) {
      auto own = lines.JobKeys[j].find(key);
      const bool fromDefaults = own == lines.JobKeys[j].end() && lines.DefaultKeys.count(key);
      const int line = own != lines.JobKeys[j].end() ? own->second
        : fromDefaults                               ? lines.DefaultKeys.at(key)
                                                     : job.Line;
      return file + ", line " + std::to_string(line) + " (job " + std::to_string(j) +
        (key.empty() ? std::string() : (fromDefaults ? ", \"defaults\" " : ", ") + ("\"" + key + "\"")) + "): ";
    };
    if (settings.contains("name") && !settings["name"].is_string())
    {
      error = where("name") + "must be a string";
      return false;
    }
    for (const char* required : { "sweep", "output" })
    {
      if (!settings.contains(required))
      {
        error = where("") + "missing \"" + required + "\"";
        return false;
      }
    }
    if (!settings["output"].is_string() || settings["output"].get<std::string>().empty())
    {
      error = where("output") + "the job's output folder must be a non-empty string";
      return false;
    }
    job.Output = (folder / settings["output"].get<std::string>()).lexically_normal().string();
    // The job's name: given, or its output folder's own name (a trailing separator dropped).
    const fs::path leaf = fs::path(job.Output).filename().empty() ? fs::path(job.Output).parent_path().filename()
                                                                  : fs::path(job.Output).filename();
    job.Name = settings.value("name", leaf.string());
    const std::string canonical = fs::weakly_canonical(job.Output).string();
    if (outputs.count(canonical))
    {
      error = where("output") + "output folder " + job.Output + " is also job " + std::to_string(outputs[canonical]) +
        "'s (line " + std::to_string(lines.Jobs[outputs[canonical]]) + ")";
      return false;
    }
    outputs[canonical] = j;
    if (names.count(job.Name))
    {
      error = where(settings.contains("name") ? "name" : "output") + "job name \"" + job.Name + "\"" +
        (settings.contains("name") ? "" : " (its output folder's name)") + " is also job " +
        std::to_string(names[job.Name]) + "'s (line " + std::to_string(lines.Jobs[names[job.Name]]) +
        "): the summary names each job once; give each a \"name\"";
      return false;
    }
    names[job.Name] = j;
    const std::string problem = ReadJob(settings, folder, *train, job);
    if (!problem.empty())
    {
      const std::size_t split = problem.find('\t'); // "key<TAB>message": the key names the line
      error = where(split == std::string::npos ? "" : problem.substr(0, split)) +
        (split == std::string::npos ? problem : problem.substr(split + 1));
      return false;
    }
    jobs.push_back(job);
  }
  return true;
}

} // namespace bigus::cli

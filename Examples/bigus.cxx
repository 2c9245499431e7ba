// bigus: command-line front end of BIGUS-VTK.
//
//   bigus info SWEEP [--calibration XML] [--transform CHAIN] [--frames FIRST LAST]
//   bigus train SWEEP -o FIELD.vtp [--holdout-every K --holdout-offset J | --frames LIST] [--time-budget S]
//               [--iterations N] ...
//   bigus render FIELD.vtp --poses SWEEP [--frames LIST] -o OUT.igs.mha
//   bigus render FIELD.vtp --plane OX OY OZ NX NY NZ [--size W H] [--spacing MM] -o slice.png|.mha
//   bigus render FIELD.vtp --volume [--spacing MM] -o volume.mha|.vti
//   bigus evaluate FIELD.vtp SWEEP [--holdout-every K --holdout-offset J | --frames LIST] --report DIR
//   bigus sweep VOLUME -o SWEEP.igs.mha [--mask-output MASK.mha] [--protocol parallel|oblique|orthogonal] ...
//   mpirun -n P bigus train SWEEP -o FIELD.vtp --distributed ...   (data-parallel: gradients summed every step)
//   bigus batch MANIFEST.json [--summary DIR]   (also under mpirun -n P: the ranks share a work queue)
//   bigus benchmark [--quick] [--section all|defaults|volume|blocks|ablations|pareto] [--output DIR]
//
// Exit codes: 0 success, 1 a bad file or a failed step (one line on stderr), 2 bad arguments.
// Outputs are written under a temporary name and renamed: an existing file is never left half-written.
//
// Each command lives in CommandLine/bigus<Command>Command.cxx (its options and what it runs); what they
// share (reading sweeps, fields and masks, failing with a message) in CommandLine/bigusCommandLine.h.
#include "bigusCommandLine.h"
#include "vtkLogger.h"
#include "vtkOutputWindow.h"

#include <CLI/CLI.hpp>

#include <vector>

int main(int argc, char** argv)
{
  // Errors are reported once, on one line, by this program; VTK's own output would repeat them.
  vtkOutputWindow::GetInstance()->SetDisplayModeToNever();
  vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);

  CLI::App app{ "BIGUS-VTK: beam-integrated Gaussian scattering for tracked freehand ultrasound" };
  app.require_subcommand(1);
  using namespace bigus::cli;
  const std::vector<Command> commands = { AddInfoCommand(app), AddTrainCommand(app), AddRenderCommand(app),
    AddEvaluateCommand(app), AddSweepCommand(app), AddFillGapsCommand(app), AddMergeCommand(app), AddBatchCommand(app),
    AddBenchmarkCommand(app, BIGUS_SOURCE_DIR) };
  try
  {
    app.parse(argc, argv);
  }
  catch (const CLI::ParseError& e)
  {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  for (const Command& command : commands)
  {
    if (command.App->parsed())
    {
      return command.Run();
    }
  }
  return 2;
}

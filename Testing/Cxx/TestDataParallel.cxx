// Data-parallel training (bigus::ProcessReduction): processes, here threads with a ThreadReduction, each render
// their share of a step's frames and sum, and take the step one process takes on all of them.
#include "bigusThreadReduction.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

TEST(Trainer, ADataParallelStepOnTwoProcessesIsOneProcessesStepOnAllTheFrames)
{
  // Two processes (threads with a ThreadReduction, as the ranks of mpirun with vtkMPIController's AllReduce) each
  // render their share of a step's frames and sum: three steps give both the same field, moments and EA-D
  // accumulators, and they are one process's steps on all the frames to the float rounding of the sums' order.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(50, 4), 0.5, heldOut);
  OptimizerState state;
  state.Field = KnownField(300, 12);
  state.ResizeToField();
  const std::vector<int> frames = { 0, 5, 9, 14, 20 };
  StepRequest request;
  request.Frames = frames.data();
  request.Count = static_cast<int>(frames.size());
  request.MeanRate = request.LogScaleRate = request.QuaternionRate = request.ReflectivityRate = 0.01;
  request.MinimumLogScale = std::log(0.01);
  request.MaximumLogScale = std::log(100.0);
  auto train = [&](ProcessReduction* reduction, std::vector<double>& losses, OptimizerState& after) {
    std::string error;
    auto engine = CreateTrainingEngine("cpu", &error);
    ASSERT_NE(engine, nullptr) << error;
    ASSERT_TRUE(
      engine->SetData(&data, &error) && engine->SetReduction(reduction, &error) && engine->Push(state, &error))
      << error;
    for (int step = 0; step < 3; ++step)
    {
      StepRequest r = request;
      r.Iteration = step;
      double loss = 0;
      EXPECT_EQ(engine->Step(r, &loss, &error), StepStatus::Done) << error;
      losses.push_back(loss);
    }
    EXPECT_TRUE(engine->Pull(after, &error)) << error;
  };
  std::vector<double> losses[3];
  OptimizerState after[3];
  train(nullptr, losses[2], after[2]);
  bigus::test::RunOnThreads(
    2, [&](int rank, ProcessReduction& reduction) { train(&reduction, losses[rank], after[rank]); });
  EXPECT_EQ(losses[0], losses[1]);
  ExpectSameField(after[0].Field, after[1].Field);
  ExpectSameField(after[0].SecondMoment, after[1].SecondMoment);
  EXPECT_EQ(after[0].Attribution, after[1].Attribution);
  EXPECT_EQ(after[0].SeenCount, after[1].SeenCount);
  EXPECT_EQ(after[0].SeenCount, after[2].SeenCount) << "the visible counts of all the frames";
  for (int step = 0; step < 3; ++step)
  {
    EXPECT_NEAR(losses[0][step], losses[2][step], 1e-6 * losses[2][step]) << "step " << step;
  }
  ASSERT_EQ(after[0].Field.Count(), after[2].Field.Count());
  double largest = 0, attribution = 0;
  for (std::size_t k = 0; k < after[0].Field.Means.size(); ++k)
  {
    largest = std::max(largest, static_cast<double>(std::abs(after[0].Field.Means[k] - after[2].Field.Means[k])));
  }
  for (std::size_t k = 0; k < after[0].Attribution.size(); ++k)
  {
    const double a = after[0].Attribution[k], b = after[2].Attribution[k];
    attribution = std::max(attribution, std::abs(a - b) / std::max(1e-12, std::abs(b)));
  }
  std::printf(
    "two processes against one: means %.3g mm apart at most, attribution %.3g relative\n", largest, attribution);
  EXPECT_LT(largest, 1e-4) << "three steps of 0.01 mm each moved the means differently";
  EXPECT_LT(attribution, 1e-4);
}

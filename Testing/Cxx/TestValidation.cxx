// The validation stage (bigusValidation.h): which training frames a run scores itself on while it trains.
#include "bigusValidation.h"

#include <gtest/gtest.h>

#include <vector>

using namespace bigus;

// ValidationFrames: every (n / 8)-th of the n training frames (every one while n < 16), at most 8, counted by hand.
// The training frames are 1, 4, 7, ... (3 m + 1 for the m-th), so that a position in TrainFrames is not taken for a
// frame.
TEST(Validation, EveryEighthOfTheTrainingFramesAtMostEight)
{
  struct Case
  {
    int Frames;
    std::vector<int> Expected;
  };
  const Case cases[] = {
    { 0, {} },                                       // no training frame, no validation frame
    { 5, { 1, 4, 7, 10, 13 } },                      // n / 8 = 0: every frame, 5 of them
    { 16, { 1, 7, 13, 19, 25, 31, 37, 43 } },        // every 2nd: positions 0, 2, ..., 14
    { 17, { 1, 7, 13, 19, 25, 31, 37, 43 } },        // every 2nd, the 9th (position 16) left out
    { 100, { 1, 37, 73, 109, 145, 181, 217, 253 } }, // every 12th: positions 0, 12, ..., 84 (96 left out)
  };
  for (const Case& c : cases)
  {
    TrainingData data;
    for (int m = 0; m < c.Frames; ++m)
    {
      data.TrainFrames.push_back(3 * m + 1);
    }
    EXPECT_EQ(ValidationFrames(data), c.Expected) << c.Frames << " training frames";
  }
}

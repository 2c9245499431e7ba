// The pieces the training engines share: Adam (bigusAdam.h) against Kingma and Ba's algorithm 1 written out
// here, the parameter-layout table (bigusFieldLayout.h) against GaussianField, and the factory's choice of the CPU
// engine for data-parallel runs.
#include "bigusAdam.h"
#include "bigusFieldLayout.h"
#include "bigusTrainingEngine.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

using namespace bigus;

namespace
{

/// Kingma and Ba 2015, algorithm 1, in double: @p steps updates of x from x0 with the gradients @p g.
double KingmaBa(double x0, const std::vector<double>& g, double alpha)
{
  const double beta1 = 0.9, beta2 = 0.999, epsilon = 1e-12;
  double x = x0, m = 0, v = 0;
  for (std::size_t k = 0; k < g.size(); ++k)
  {
    const int t = static_cast<int>(k) + 1;
    m = beta1 * m + (1 - beta1) * g[k];
    v = beta2 * v + (1 - beta2) * g[k] * g[k];
    const double mHat = m / (1 - std::pow(beta1, t));
    const double vHat = v / (1 - std::pow(beta2, t));
    x = x - alpha * mHat / (std::sqrt(vHat) + epsilon);
  }
  return x;
}

std::vector<double> Gradients(unsigned seed, int count)
{
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.5, 2.0);
  std::vector<double> g(count);
  for (double& v : g)
  {
    v = normal(rng);
  }
  return g;
}

} // namespace

TEST(Adam, TheBiasCorrectionsAreOneLessThePowersOfTheBetas)
{
  for (int t : { 1, 2, 10, 1000 })
  {
    const AdamBias bias = AdamBiasAt(t);
    EXPECT_DOUBLE_EQ(bias.C1, 1 - std::pow(0.9, t)) << t;
    EXPECT_DOUBLE_EQ(bias.C2, 1 - std::pow(0.999, t)) << t;
  }
}

TEST(Adam, InDoubleItIsAlgorithmOneOfKingmaAndBa)
{
  const std::vector<double> g = Gradients(1, 200);
  double x = 1.5, m = 0, v = 0;
  for (std::size_t k = 0; k < g.size(); ++k)
  {
    AdamUpdate(x, m, v, g[k], 0.01, AdamBiasAt(static_cast<int>(k) + 1));
  }
  EXPECT_DOUBLE_EQ(x, KingmaBa(1.5, g, 0.01));
}

TEST(Adam, InFloatItIsAlgorithmOneToFloatRounding)
{
  // The engines' case: parameter and moments stored as float, each update computed in double.
  const std::vector<double> g = Gradients(2, 200);
  float x = 1.5f, m = 0, v = 0;
  for (std::size_t k = 0; k < g.size(); ++k)
  {
    AdamUpdate(x, m, v, static_cast<float>(g[k]), 0.01, AdamBiasAt(static_cast<int>(k) + 1));
  }
  std::vector<double> rounded(g.size());
  for (std::size_t k = 0; k < g.size(); ++k)
  {
    rounded[k] = static_cast<float>(g[k]);
  }
  const double expected = KingmaBa(1.5, rounded, 0.01);
  EXPECT_NEAR(x, expected, 1e-5 * std::abs(expected));
  EXPECT_NE(x, 1.5f);
}

TEST(Adam, TheFirstStepMovesByTheLearningRateAgainstTheGradient)
{
  // Kingma and Ba, section 2.1: with zero moments the first step is alpha sign(g) (to epsilon).
  for (double g : { -3.0, 1e-4, 250.0 })
  {
    double x = 0, m = 0, v = 0;
    AdamUpdate(x, m, v, g, 0.1, AdamBiasAt(1));
    EXPECT_NEAR(x, g > 0 ? -0.1 : 0.1, 1e-9) << g;
  }
}

TEST(FieldLayout, TheTableIsGaussianFieldsArraysOneAfterTheOther)
{
  GaussianField field;
  field.Resize(5);
  const std::int64_t n = field.Count();
  EXPECT_EQ(&field.Group(MeanGroup), &field.Means);
  EXPECT_EQ(&field.Group(LogScaleGroup), &field.LogScales);
  EXPECT_EQ(&field.Group(QuaternionGroup), &field.Quaternions);
  EXPECT_EQ(&field.Group(ReflectivityGroup), &field.Reflectivities);
  int first = 0;
  for (int q = 0; q < FieldGroups; ++q)
  {
    EXPECT_EQ(static_cast<std::int64_t>(field.Group(q).size()), FieldGroupWidth(q) * n) << q;
    EXPECT_EQ(FieldGroupFirst(q), first) << q;
    first += FieldGroupWidth(q);
  }
  EXPECT_EQ(first, FieldParameters);
  // FieldEntry visits every entry of a packed array once; FieldGradientsAt points at the groups' starts.
  std::vector<int> visits(FieldParameters * n, 0);
  for (std::int64_t i = 0; i < n; ++i)
  {
    for (int q = 0; q < FieldGroups; ++q)
    {
      for (int c = 0; c < FieldGroupWidth(q); ++c)
      {
        ++visits[FieldEntry(n, i, q, c)];
      }
    }
  }
  EXPECT_EQ(visits, std::vector<int>(FieldParameters * n, 1));
  std::vector<float> packed(FieldParameters * n, 0.f);
  const FieldGradients g = FieldGradientsAt(packed.data(), n);
  EXPECT_EQ(g.Means, packed.data());
  EXPECT_EQ(g.LogScales, packed.data() + 3 * n);
  EXPECT_EQ(g.Quaternions, packed.data() + 6 * n);
  EXPECT_EQ(g.Reflectivities, packed.data() + 10 * n);
  EXPECT_FALSE(FieldGradientTouched(packed.data(), n, 2));
  packed[FieldEntry(n, 2, QuaternionGroup, 3)] = 1e-30f;
  EXPECT_TRUE(FieldGradientTouched(packed.data(), n, 2));
  EXPECT_FALSE(FieldGradientTouched(packed.data(), n, 3));
}

namespace
{
int RegisteredEnginesMade = 0;

/// A backend's own engine (as the device-resident CUDA engine registers), counted.
std::unique_ptr<TrainingEngine> MakeRegisteredEngine(std::string*)
{
  ++RegisteredEnginesMade;
  return CreateCpuTrainingEngine(CreateCpuRenderer());
}

/// Two processes, never asked to sum (SetReduction only keeps it).
class TwoProcesses : public ProcessReduction
{
public:
  int Rank() const override { return 0; }
  int Size() const override { return 2; }
  bool Sum(float*, std::size_t, std::string*) override { return false; }
  bool Sum(double*, std::size_t, std::string*) override { return false; }
  bool Maximum(double*, std::size_t, std::string*) override { return false; }
  bool Maximum(unsigned char*, std::size_t, std::string*) override { return false; }
};
} // namespace

TEST(TrainingEngineFactory, DataParallelRunsGetTheCpuEngineOverTheBackendsRenderer)
{
  // In this test process "cpu" stands for a backend with an engine of its own (as "cuda" registers one).
  RegisterTrainingEngine("cpu", &MakeRegisteredEngine);
  std::string error;
  ASSERT_NE(CreateTrainingEngine("cpu", &error), nullptr) << error;
  EXPECT_EQ(RegisteredEnginesMade, 1);
  std::unique_ptr<TrainingEngine> engine = CreateTrainingEngine("cpu", &error, nullptr, true);
  ASSERT_NE(engine, nullptr) << error;
  EXPECT_EQ(RegisteredEnginesMade, 1) << "the registered engine is not made for a data-parallel run";
  EXPECT_STREQ(engine->GetName(), "cpu"); // the CPU engine names its renderer's backend
  TwoProcesses two;
  EXPECT_TRUE(engine->SetReduction(&two, &error)) << error;
}

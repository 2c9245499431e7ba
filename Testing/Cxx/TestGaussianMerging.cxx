// The merge of neighbouring Gaussians (bigusGaussianMerging.h) against independent truth: the pair's mass,
// centre and second moment and the merge's integrated squared error by quadrature on a 3D grid; a field of
// twins merged to the field they came from, rendered by the CPU renderer; pairs that must not merge.
#include "bigusGaussianFieldData.h"
#include "bigusGaussianMerging.h"
#include "bigusRenderer.h"
#include "bigusTestUtilities.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldMerge.h"
#include "vtkIntArray.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkStringArray.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

using namespace bigus;

namespace
{
GaussianParams MakeGaussian(
  const std::array<double, 3>& mean, const std::array<double, 3>& scales, const std::array<double, 4>& q, double r)
{
  GaussianParams g{};
  for (int k = 0; k < 3; ++k)
  {
    g.Mean[k] = mean[k];
    g.LogScale[k] = std::log(scales[k]);
  }
  for (int k = 0; k < 4; ++k)
  {
    g.Quaternion[k] = q[k];
  }
  g.Reflectivity = r;
  return g;
}

/// The rotation of @p g (its quaternion normalised).
void Rotation(const GaussianParams& g, double R[3][3])
{
  const double n = std::sqrt(g.Quaternion[0] * g.Quaternion[0] + g.Quaternion[1] * g.Quaternion[1] +
    g.Quaternion[2] * g.Quaternion[2] + g.Quaternion[3] * g.Quaternion[3]);
  const double q[4] = { g.Quaternion[0] / n, g.Quaternion[1] / n, g.Quaternion[2] / n, g.Quaternion[3] / n };
  QuaternionToMatrix(q, R);
}

/// g(x) = r exp(-1/2 (x - mu)^T Sigma^-1 (x - mu)), evaluated through its own axes.
double Evaluate(const GaussianParams& g, const double x[3])
{
  double R[3][3];
  Rotation(g, R);
  double e = 0;
  for (int k = 0; k < 3; ++k)
  {
    double local = 0;
    for (int i = 0; i < 3; ++i)
    {
      local += R[i][k] * (x[i] - g.Mean[i]);
    }
    e += std::pow(local / std::exp(g.LogScale[k]), 2);
  }
  return g.Reflectivity * std::exp(-0.5 * e);
}

/// Quadrature on a regular grid (spectrally accurate for Gaussians well inside it).
struct Quadrature
{
  double Mass = 0;
  double Mean[3] = { 0, 0, 0 };
  double Second[3][3] = {};
  double PairNorm = 0, Error = 0; ///< ||a + b||^2 and ||a + b - m||^2
};

Quadrature Integrate(const GaussianParams& a, const GaussianParams& b, const GaussianParams& m)
{
  constexpr int N = 170;
  constexpr double Lo = -6, Hi = 6, h = (Hi - Lo) / N;
  Quadrature q;
  double first[3] = { 0, 0, 0 }, second[3][3] = {};
  for (int i = 0; i < N; ++i)
  {
    for (int j = 0; j < N; ++j)
    {
      for (int k = 0; k < N; ++k)
      {
        const double x[3] = { Lo + (i + 0.5) * h, Lo + (j + 0.5) * h, Lo + (k + 0.5) * h };
        const double pair = Evaluate(a, x) + Evaluate(b, x), merged = Evaluate(m, x);
        q.Mass += pair;
        q.PairNorm += pair * pair;
        q.Error += (pair - merged) * (pair - merged);
        for (int r = 0; r < 3; ++r)
        {
          first[r] += pair * x[r];
          for (int c = 0; c < 3; ++c)
          {
            second[r][c] += pair * x[r] * x[c];
          }
        }
      }
    }
  }
  for (int r = 0; r < 3; ++r)
  {
    q.Mean[r] = first[r] / q.Mass;
  }
  for (int r = 0; r < 3; ++r)
  {
    for (int c = 0; c < 3; ++c)
    {
      q.Second[r][c] = second[r][c] / q.Mass - q.Mean[r] * q.Mean[c];
    }
  }
  const double volume = h * h * h;
  q.Mass *= volume;
  q.PairNorm *= volume;
  q.Error *= volume;
  return q;
}

/// Mass, mean and covariance of one Gaussian in closed form (to compare with the pair's quadrature).
void Moments(const GaussianParams& g, double& mass, double covariance[3][3])
{
  double R[3][3];
  Rotation(g, R);
  double det = 1;
  for (int k = 0; k < 3; ++k)
  {
    det *= std::exp(2 * g.LogScale[k]);
  }
  mass = g.Reflectivity * std::pow(2 * M_PI, 1.5) * std::sqrt(det);
  for (int r = 0; r < 3; ++r)
  {
    for (int c = 0; c < 3; ++c)
    {
      covariance[r][c] = 0;
      for (int k = 0; k < 3; ++k)
      {
        covariance[r][c] += R[r][k] * R[c][k] * std::exp(2 * g.LogScale[k]);
      }
    }
  }
}

/// 150 Gaussians 2 mm apart (scales 0.2 to 0.5 mm: far from each other) in @p field, and in @p twins each cut in
/// two halves 1 % of its smallest scale apart along a random direction.
void FieldAndTwins(GaussianField& field, GaussianField& twins)
{
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::normal_distribution<double> normal(0, 1);
  for (int i = 0; i < 150; ++i)
  {
    const double mean[3] = { 2.0 * (i % 10), 2.0 * ((i / 10) % 5), 2.0 * (i / 50) };
    double scales[3], smallest = 1;
    for (double& s : scales)
    {
      s = 0.2 + 0.3 * uniform(rng);
      smallest = std::min(smallest, s);
    }
    const double r = (i % 3 == 0 ? -1 : 1) * (0.2 + uniform(rng));
    AppendRandomRotation(field, rng, normal);
    double d[3] = { normal(rng), normal(rng), normal(rng) };
    const double dn = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int copy = 0; copy < 2; ++copy)
    {
      for (int k = 0; k < 3; ++k)
      {
        twins.Means.push_back(static_cast<float>(mean[k] + (copy ? 0.005 : -0.005) * smallest * d[k] / dn));
        twins.LogScales.push_back(static_cast<float>(std::log(scales[k])));
      }
      twins.Quaternions.insert(twins.Quaternions.end(), field.Quaternions.end() - 4, field.Quaternions.end());
      twins.Reflectivities.push_back(static_cast<float>(0.5 * r));
    }
    for (int k = 0; k < 3; ++k)
    {
      field.Means.push_back(static_cast<float>(mean[k]));
      field.LogScales.push_back(static_cast<float>(std::log(scales[k])));
    }
    field.Reflectivities.push_back(static_cast<float>(r));
  }
}
}

TEST(GaussianMerging, PairKeepsMassCentreAndSecondMomentAndItsErrorMatchesQuadrature)
{
  struct Case
  {
    GaussianParams A, B;
  };
  const Case cases[] = {
    // overlapping ellipsoids turned differently, positive
    { MakeGaussian({ -0.4, 0.1, 0.2 }, { 0.9, 0.5, 0.3 }, { 0.9, 0.2, -0.3, 0.1 }, 0.8),
      MakeGaussian({ 0.5, -0.2, 0.0 }, { 0.6, 0.7, 0.4 }, { 0.3, -0.5, 0.6, 0.4 }, 0.5) },
    // a needle and a pancake, negative
    { MakeGaussian({ 0.0, 0.0, -0.3 }, { 1.2, 0.15, 0.15 }, { 1, 0, 0, 0 }, -0.6),
      MakeGaussian({ 0.2, 0.3, 0.3 }, { 0.8, 0.8, 0.12 }, { 0.7, 0.7, 0, 0 }, -1.1) },
    // far apart: a poor merge
    { MakeGaussian({ -1.6, 0, 0 }, { 0.4, 0.4, 0.4 }, { 1, 0, 0, 0 }, 1.0),
      MakeGaussian({ 1.6, 0, 0 }, { 0.4, 0.4, 0.4 }, { 1, 0, 0, 0 }, 1.0) },
  };
  for (const Case& c : cases)
  {
    const GaussianPairMerge merge = MergeGaussianPair(c.A, c.B);
    ASSERT_LT(merge.Error, 1.0);
    const Quadrature q = Integrate(c.A, c.B, merge.Merged);
    double mass, covariance[3][3];
    Moments(merge.Merged, mass, covariance);
    EXPECT_NEAR(mass, q.Mass, 1e-6 * std::abs(q.Mass));
    for (int r = 0; r < 3; ++r)
    {
      EXPECT_NEAR(merge.Merged.Mean[r], q.Mean[r], 1e-6);
      for (int k = 0; k < 3; ++k)
      {
        EXPECT_NEAR(covariance[r][k], q.Second[r][k], 1e-5);
      }
    }
    EXPECT_NEAR(merge.Error, q.Error / q.PairNorm, 1e-6 + 1e-5 * merge.Error);
  }
  // The far pair merges badly, the overlapping ones well.
  EXPECT_GT(MergeGaussianPair(cases[2].A, cases[2].B).Error, 0.3);
  EXPECT_LT(MergeGaussianPair(cases[0].A, cases[0].B).Error, 0.1);
}

TEST(GaussianMerging, IdenticalTwinsMergeExactlyAndOppositeSignsNever)
{
  const GaussianParams a = MakeGaussian({ 1, 2, 3 }, { 0.5, 0.2, 0.1 }, { 0.5, 0.5, -0.5, 0.5 }, 0.3);
  const GaussianPairMerge merge = MergeGaussianPair(a, a);
  EXPECT_NEAR(merge.Error, 0, 1e-12);
  EXPECT_NEAR(merge.Merged.Reflectivity, 0.6, 1e-12);
  double ma, ca[3][3], mm, cm[3][3];
  Moments(a, ma, ca);
  Moments(merge.Merged, mm, cm);
  for (int r = 0; r < 3; ++r)
  {
    EXPECT_NEAR(merge.Merged.Mean[r], a.Mean[r], 1e-12);
    for (int k = 0; k < 3; ++k)
    {
      EXPECT_NEAR(cm[r][k], ca[r][k], 1e-12);
    }
  }
  GaussianParams b = a;
  b.Reflectivity = -0.3;
  EXPECT_EQ(MergeGaussianPair(a, b).Error, 1.0);
  b.Reflectivity = 0;
  EXPECT_EQ(MergeGaussianPair(a, b).Error, 1.0);
}

TEST(GaussianMerging, AMergeThinnerThanTheSmallestScaleIsJudgedAsTheClampedGaussianItStores)
{
  // Twins 1e-7 mm thick along z: the moment-matched merge is as thin, but a stored scale is at least 1e-6 mm, so the
  // field would hold a Gaussian 10 times thicker (the same mass). Its error is that Gaussian's: the x and y factors
  // of the pair and the merge are equal, so the relative integrated squared error is that of the z factors alone,
  // f(z) = 2 r exp(-z^2 / 2 s^2) against h(z) = 2 r (s / t) exp(-z^2 / 2 t^2), with s = 1e-7, t = 1e-6 (mm):
  // ||f||^2 = 4 r^2 sqrt(pi) s, ||h||^2 = 4 r^2 (s / t)^2 sqrt(pi) t,
  // <f, h> = 4 r^2 (s / t) sqrt(2 pi) s t / sqrt(s^2 + t^2).
  const double s = 1e-7, t = 1e-6;
  const GaussianParams a = MakeGaussian({ 1, 2, 3 }, { 0.5, 0.2, s }, { 1, 0, 0, 0 }, 0.3);
  const double ff = std::sqrt(M_PI) * s, hh = (s / t) * (s / t) * std::sqrt(M_PI) * t;
  const double fh = (s / t) * std::sqrt(2 * M_PI) * s * t / std::sqrt(s * s + t * t);
  const double expected = (ff + hh - 2 * fh) / ff;
  const GaussianPairMerge merge = MergeGaussianPair(a, a);
  EXPECT_NEAR(merge.Error, expected, 1e-9) << "the unclamped merge would err by 0";
  EXPECT_GT(merge.Error, 0.3);
  EXPECT_NEAR(
    std::exp(merge.Merged.LogScale[0]) * std::exp(merge.Merged.LogScale[1]) * std::exp(merge.Merged.LogScale[2]),
    0.5 * 0.2 * t, 1e-9 * 0.5 * 0.2 * t);
  EXPECT_NEAR(merge.Merged.Reflectivity, 0.6 * s / t, 1e-9);
  // Twice as thick as the clamp: nothing is clamped, the twins merge exactly.
  const GaussianParams b = MakeGaussian({ 1, 2, 3 }, { 0.5, 0.2, 2 * t }, { 1, 0, 0, 0 }, 0.3);
  EXPECT_NEAR(MergeGaussianPair(b, b).Error, 0, 1e-9);
}

TEST(GaussianMerging, FieldOfTwinsMergesBackToTheFieldItCameFrom)
{
  // Each Gaussian of a field cut into two halves (FieldAndTwins): merging must undo exactly the cuts, and the
  // field must render as the uncut one.
  GaussianField field, twins;
  FieldAndTwins(field, twins);
  GaussianField merged = twins;
  GaussianMergeSettings settings;
  settings.Tolerance = 1e-3;
  const GaussianMergeReport report = MergeGaussians(merged, settings);
  EXPECT_EQ(report.Before, 300);
  EXPECT_EQ(report.Merged, 150);
  ASSERT_EQ(merged.Count(), 150);
  // Merged in order: Gaussian i of the merged field is the uncut Gaussian i.
  for (std::int64_t i = 0; i < 150; ++i)
  {
    EXPECT_NEAR(merged.Reflectivities[i], field.Reflectivities[i], 1e-4 * std::abs(field.Reflectivities[i]));
    for (int k = 0; k < 3; ++k)
    {
      EXPECT_NEAR(merged.Means[3 * i + k], field.Means[3 * i + k], 1e-4);
    }
  }
  // Rendered on oblique slices through the rows of Gaussians: the merged field as the uncut one.
  auto renderer = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = 0.2;
  o.Gamma = 1;
  const int W = 120, H = 60;
  for (double z : { 0.0, 1.7, 2.2 })
  {
    SliceGeometry g;
    const double pose[16] = { 0.2, 0, 0, -2, 0, 0.2 * std::cos(0.3), 0, -1, 0, 0.2 * std::sin(0.3), 0, z, 0, 0, 0, 1 };
    std::copy(pose, pose + 16, g.ImageToReference);
    g.Width = W;
    g.Height = H;
    std::vector<float> S0(W * H), S1(W * H), I(W * H);
    ASSERT_TRUE(renderer->Forward(field.View(), &g, 1, o, S0.data(), I.data(), nullptr, nullptr));
    ASSERT_TRUE(renderer->Forward(merged.View(), &g, 1, o, S1.data(), I.data(), nullptr, nullptr));
    double peak = 0, difference = 0;
    for (int p = 0; p < W * H; ++p)
    {
      peak = std::max(peak, double(std::abs(S0[p])));
      difference = std::max(difference, double(std::abs(S1[p] - S0[p])));
    }
    EXPECT_GT(peak, 0.05) << "slice at z = " << z;
    EXPECT_LT(difference, 1e-3 * peak) << "slice at z = " << z;
  }
  // The uncut field has nothing to merge at this tolerance (its Gaussians are 4 to 10 scales apart), nor does
  // any field at tolerance 0.
  GaussianField apart = field;
  EXPECT_EQ(MergeGaussians(apart, settings).Merged, 0);
  EXPECT_EQ(apart.Count(), 150);
  GaussianField untouched = twins;
  EXPECT_EQ(MergeGaussians(untouched, GaussianMergeSettings()).Merged, 0);
  ExpectSameField(untouched, twins);
}

TEST(GaussianMerging, ChainsMergeOverPassesKeepingTheTotalMomentsAndTheResultIsDeterministic)
{
  // Eight equal, overlapping Gaussians in a row 0.1 scales apart merge over passes into one. Every
  // moment-matched merge keeps the mass, centre and second moment of what it merges, so the last Gaussian holds
  // the row's: mass 8 r s1 s2 s3, centre 0.175 mm, variance along the row s1^2 + the positions' variance.
  GaussianField row;
  for (int i = 0; i < 8; ++i)
  {
    row.Means.insert(row.Means.end(), { 0.05f * i, 0.f, 0.f });
    row.LogScales.insert(row.LogScales.end(), { std::log(0.5f), std::log(0.3f), std::log(0.3f) });
    row.Quaternions.insert(row.Quaternions.end(), { 1.f, 0.f, 0.f, 0.f });
    row.Reflectivities.push_back(0.25f);
  }
  GaussianMergeSettings settings;
  settings.Tolerance = 1e-2;
  settings.MaximumPasses = 10;
  GaussianField a = row, b = row;
  const GaussianMergeReport report = MergeGaussians(a, settings);
  MergeGaussians(b, settings);
  ExpectSameField(a, b);
  EXPECT_EQ(report.Merged, 7);
  EXPECT_GE(report.Passes, 3);
  ASSERT_EQ(a.Count(), 1);
  const GaussianParams g =
    LoadGaussian(a.Means.data(), a.LogScales.data(), a.Quaternions.data(), a.Reflectivities.data(), 0);
  double mass, covariance[3][3];
  Moments(g, mass, covariance);
  const double expected = 8 * 0.25 * std::pow(2 * M_PI, 1.5) * 0.5 * 0.3 * 0.3;
  EXPECT_NEAR(mass, expected, 1e-5 * expected);
  EXPECT_NEAR(g.Mean[0], 0.175, 1e-5);
  const double positions = 0.05 * 0.05 * (64 - 1) / 12.0;
  EXPECT_NEAR(covariance[0][0], 0.25 + positions, 1e-5);
  EXPECT_NEAR(covariance[1][1], 0.09, 1e-5);
  EXPECT_NEAR(covariance[0][1], 0, 1e-6);
}

TEST(GaussianMerging, TheFilterMergesAFieldAndPassesItsFieldData)
{
  // vtkGaussianFieldMerge in a pipeline: the twins merged back, the field data passed with GaussianMerge added;
  // an input that is no field fails the request with the missing array's name and leaves the output empty.
  GaussianField field, twins;
  FieldAndTwins(field, twins);
  FieldModel model;
  model.ElevationSigma = 0.4;
  vtkNew<vtkPolyData> input;
  FieldToPolyData(twins, model, input);
  vtkNew<vtkIntArray> frames;
  frames->SetName("TrainingFrames");
  frames->InsertNextValue(3);
  input->GetFieldData()->AddArray(frames);
  vtkNew<vtkGaussianFieldMerge> merge;
  merge->SetInputData(input);
  merge->SetTolerance(1e-3);
  merge->Update();
  vtkPolyData* output = merge->GetOutput();
  EXPECT_EQ(merge->GetMergedPairs(), 150);
  EXPECT_EQ(output->GetNumberOfPoints(), 150);
  EXPECT_EQ(output->GetNumberOfVerts(), 150);
  ASSERT_NE(output->GetFieldData()->GetArray("TrainingFrames"), nullptr);
  EXPECT_EQ(output->GetFieldData()->GetArray("TrainingFrames")->GetTuple1(0), 3);
  ASSERT_NE(output->GetFieldData()->GetArray("ElevationSigma"), nullptr);
  EXPECT_NEAR(output->GetFieldData()->GetArray("ElevationSigma")->GetTuple1(0), 0.4, 1e-12);
  auto* note = vtkStringArray::SafeDownCast(output->GetFieldData()->GetAbstractArray("GaussianMerge"));
  ASSERT_NE(note, nullptr);
  EXPECT_EQ(note->GetValue(0).rfind("150 pairs merged of 300 Gaussians", 0), 0u) << note->GetValue(0);
  GaussianField back;
  FieldModel backModel;
  std::string error;
  ASSERT_TRUE(FieldFromPolyData(output, back, backModel, &error)) << error;
  for (std::int64_t i = 0; i < 150; ++i)
  {
    EXPECT_NEAR(back.Reflectivities[i], field.Reflectivities[i], 1e-4 * std::abs(field.Reflectivities[i]));
  }

  vtkNew<vtkPolyData> bare;
  bare->SetPoints(input->GetPoints());
  vtkNew<vtkGaussianFieldMerge> failing;
  bigus_test::MessageCollector* messages = bigus_test::MessageCollector::New();
  messages->Watch(failing);
  failing->SetInputData(bare);
  failing->Update();
  ASSERT_EQ(messages->Errors.size(), 1u);
  EXPECT_NE(messages->Errors.front().find("Scale"), std::string::npos) << messages->Errors.front();
  messages->Delete();
  EXPECT_EQ(failing->GetOutput()->GetNumberOfPoints(), 0);
}

/**
 * @class   vtkGaussianFieldMerge
 * @brief   Merges neighbouring Gaussians of a field that one Gaussian represents: a smaller field that renders
 *          nearly as before (bigus::MergeGaussians; `bigus merge` on the command line).
 *
 * Input and output: a Gaussian field (vtkPolyData as vtkGaussianFieldTrainer writes it: points = means in mm,
 * point data Scale, Rotation, Reflectivity). Pairs of one sign among each Gaussian's Neighbours nearest means are
 * replaced by their moment-matched Gaussian (its mass, centre of mass and second moment; Runnalls 2007) while the
 * pair's relative integrated squared error ||a + b - merged||^2 / ||a + b||^2 over 3D (closed form; Williams and
 * Maybeck 2003) stays below Tolerance, over at most MaximumPasses passes. The field data of the input (training
 * geometry, ElevationSigma, Gamma, ...) is passed on, with the string array `GaussianMerge` saying what was merged.
 * vtkGaussianFieldTrainer merges at 0.001 at the end of every run; larger tolerances trade PSNR for fewer
 * Gaussians (docs/FINDINGS.md, "Merging").
 * A malformed field fails the request with vtkErrorMacro naming the array and leaves the output empty.
 */
#ifndef vtkGaussianFieldMerge_h
#define vtkGaussianFieldMerge_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkPolyDataAlgorithm.h"

class BIGUSFILTERS_EXPORT vtkGaussianFieldMerge : public vtkPolyDataAlgorithm
{
public:
  static vtkGaussianFieldMerge* New();
  vtkTypeMacro(vtkGaussianFieldMerge, vtkPolyDataAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{
  /// The largest relative integrated squared error of a merge (default 0.01; 0 merges nothing).
  vtkSetClampMacro(Tolerance, double, 0.0, 1.0);
  vtkGetMacro(Tolerance, double);
  ///@}

  ///@{
  /// Candidates of each Gaussian: the Gaussians with the nearest means (default 8).
  vtkSetClampMacro(Neighbours, int, 1, 64);
  vtkGetMacro(Neighbours, int);
  ///@}

  ///@{
  /// The most passes over the field (default 4); each merges a Gaussian at most once, errors add up over passes.
  vtkSetClampMacro(MaximumPasses, int, 1, 100);
  vtkGetMacro(MaximumPasses, int);
  ///@}

  /// Pairs merged by the last execute (the output holds as many Gaussians fewer than the input).
  vtkGetMacro(MergedPairs, vtkIdType);

protected:
  vtkGaussianFieldMerge();
  ~vtkGaussianFieldMerge() override = default;

  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

private:
  vtkGaussianFieldMerge(const vtkGaussianFieldMerge&) = delete;
  void operator=(const vtkGaussianFieldMerge&) = delete;

  double Tolerance = 0.01;
  int Neighbours;    // from bigus::GaussianMergeSettings
  int MaximumPasses; // from bigus::GaussianMergeSettings
  vtkIdType MergedPairs = 0;
};

#endif

/**
 * @file bigusReferenceGeometry.h
 * @brief The render geometry of a plane of Testing/Data/Reference/reference.json applied to a
 *        vtkGaussianFieldReslice, shared by TestReferenceResults and TestGaussianFieldRegressionImages.
 */
#ifndef bigusReferenceGeometry_h
#define bigusReferenceGeometry_h

#include "vtkGaussianFieldReslice.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"

#include <nlohmann/json.hpp>

#include <vector>

namespace bigus_test
{
/**
 * Sets @p reslice's axes, output spacing, origin, extent and dimensionality from @p plane (an entry
 * of reference.json's "planes"; reslice_axes row-major 4 x 4, identity when absent; origin and extent
 * left at the filter's defaults when absent), the plane moved @p normalShift mm along its normal.
 */
inline void ApplyReferenceGeometry(
  vtkGaussianFieldReslice* reslice, const nlohmann::json& plane, double normalShift = 0)
{
  vtkNew<vtkMatrix4x4> axes;
  if (plane.contains("reslice_axes"))
  {
    const std::vector<double> m = plane["reslice_axes"];
    axes->DeepCopy(m.data());
  }
  for (int r = 0; r < 3; ++r)
  {
    axes->SetElement(r, 3, axes->GetElement(r, 3) + normalShift * axes->GetElement(r, 2));
  }
  reslice->SetResliceAxes(axes);
  const std::vector<double> spacing = plane["output_spacing"];
  reslice->SetOutputSpacing(spacing.data());
  if (plane.contains("output_origin"))
  {
    const std::vector<double> origin = plane["output_origin"];
    reslice->SetOutputOrigin(origin.data());
  }
  if (plane.contains("output_extent"))
  {
    const std::vector<int> extent = plane["output_extent"];
    reslice->SetOutputExtent(extent.data());
  }
  reslice->SetOutputDimensionality(plane["output_dimensionality"].get<int>());
}
}

#endif

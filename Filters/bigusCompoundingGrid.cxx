// vtkUltrasoundVolumeCompounder's frame plans (frames, poses, clip rectangle of each sweep) and output grid.
#include "bigusVolumeCompounding.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkPointData.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace bigus::compounding
{
namespace
{
/// A pose that maps pixels to mm: finite, affine, with image axes of non-zero length that are not
/// parallel. Returns the reason when it is not.
std::string CheckPose(const double m[16])
{
  for (int e = 0; e < 16; ++e)
  {
    if (!std::isfinite(m[e]))
    {
      return "a non-finite element";
    }
  }
  if (std::abs(m[12]) > 1e-9 || std::abs(m[13]) > 1e-9 || std::abs(m[14]) > 1e-9 || std::abs(m[15] - 1) > 1e-9)
  {
    return "a last row other than 0 0 0 1 (not affine)";
  }
  const double u[3] = { m[0], m[4], m[8] };
  const double v[3] = { m[1], m[5], m[9] };
  const double nu = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
  const double nv = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const double cross[3] = { u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0] };
  const double area = std::sqrt(cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]);
  if (!(nu > 0) || !(nv > 0) || !(area > 1e-6 * nu * nv))
  {
    return "a singular pixel-to-mm map (image axes of zero length or parallel)";
  }
  return "";
}

bool MakePlan(vtkImageData* input, vtkIdList* list, const int clipOrigin[2], const int clipSize[2], FramePlan& plan,
  std::string& error)
{
  vtkDataArray* scalars = input ? input->GetPointData()->GetScalars() : nullptr;
  if (!scalars || scalars->GetNumberOfTuples() == 0)
  {
    error = "input 0 must be a tracked frame sequence with pixels (W x H x N)";
    return false;
  }
  if (scalars->GetNumberOfComponents() != 1)
  {
    error = "the frames must have one-component scalars, not " + std::to_string(scalars->GetNumberOfComponents());
    return false;
  }
  int dims[3];
  input->GetDimensions(dims);
  plan.Width = dims[0];
  plan.Height = dims[1];
  plan.Frames = dims[2];
  vtkFieldData* fields = input->GetFieldData();
  vtkDataArray* poses = fields ? fields->GetArray("ImageToReference") : nullptr;
  if (!poses)
  {
    error = "the sequence has no ImageToReference field data (N x 16 doubles)";
    return false;
  }
  if (poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() != dims[2])
  {
    std::ostringstream text;
    text << "ImageToReference must hold " << dims[2] << " tuples of 16 values (one per frame), not "
         << poses->GetNumberOfTuples() << " of " << poses->GetNumberOfComponents();
    error = text.str();
    return false;
  }
  vtkDataArray* valid = fields->GetArray("FrameValid");
  if (valid && valid->GetNumberOfTuples() != dims[2])
  {
    valid = nullptr;
  }
  std::vector<vtkIdType> frames;
  if (list && list->GetNumberOfIds() > 0)
  {
    for (vtkIdType k = 0; k < list->GetNumberOfIds(); ++k)
    {
      const vtkIdType f = list->GetId(k);
      if (f < 0 || f >= dims[2])
      {
        error = "frame " + std::to_string(f) + " of the frame list is outside the " + std::to_string(dims[2]) +
          " frames of the sequence";
        return false;
      }
      frames.push_back(f);
    }
  }
  else
  {
    for (vtkIdType f = 0; f < dims[2]; ++f)
    {
      frames.push_back(f);
    }
  }
  plan.Inserted.clear();
  plan.Poses.clear();
  plan.SkippedInvalid.clear();
  for (vtkIdType f : frames)
  {
    if (valid && valid->GetTuple1(f) == 0)
    {
      plan.SkippedInvalid.push_back(f);
      continue;
    }
    double m[16];
    poses->GetTuple(f, m);
    const std::string problem = CheckPose(m);
    if (!problem.empty())
    {
      error = "frame " + std::to_string(f) + ": ImageToReference has " + problem;
      return false;
    }
    std::array<double, 12> rows;
    std::copy(m, m + 12, rows.begin());
    plan.Inserted.push_back(f);
    plan.Poses.push_back(rows);
  }
  if (plan.Inserted.empty())
  {
    error = "no valid frame to insert (every listed frame has FrameValid = 0)";
    return false;
  }
  // PLUS's clip convention (vtkPlusVolumeReconstructor::AddImageToExtent, GetClipExtent): the far
  // edge origin + size is included, then clamped to the image.
  plan.Clip[0] = 0;
  plan.Clip[1] = dims[0] - 1;
  plan.Clip[2] = 0;
  plan.Clip[3] = dims[1] - 1;
  if (clipSize[0] > 0 && clipSize[1] > 0)
  {
    plan.Clip[0] = std::max(0, clipOrigin[0]);
    plan.Clip[1] = std::min(dims[0] - 1, clipOrigin[0] + clipSize[0]);
    plan.Clip[2] = std::max(0, clipOrigin[1]);
    plan.Clip[3] = std::min(dims[1] - 1, clipOrigin[1] + clipSize[1]);
    if (plan.Clip[0] > plan.Clip[1] || plan.Clip[2] > plan.Clip[3])
    {
      std::ostringstream text;
      text << "the clip rectangle (origin " << clipOrigin[0] << " " << clipOrigin[1] << ", size " << clipSize[0] << " "
           << clipSize[1] << ") lies outside the " << dims[0] << " x " << dims[1] << " frames";
      error = text.str();
      return false;
    }
  }
  return true;
}
}

bool MakePlans(vtkInformationVector* inputs, vtkIdList* list, const int clipOrigin[2], const int clipSize[2],
  std::vector<FramePlan>& plans, std::string& error)
{
  plans.clear();
  const int sweeps = inputs->GetNumberOfInformationObjects();
  vtkIdType first = 0; // index of the sweep's first frame among all sweeps' frames
  for (int k = 0; k < sweeps; ++k)
  {
    vtkImageData* input = vtkImageData::GetData(inputs, k);
    int dims[3] = { 0, 0, 0 };
    if (input)
    {
      input->GetDimensions(dims);
    }
    vtkNew<vtkIdList> local;
    for (vtkIdType m = 0; list && m < list->GetNumberOfIds(); ++m)
    {
      const vtkIdType f = list->GetId(m);
      if (f >= first && f < first + dims[2])
      {
        local->InsertNextId(f - first);
      }
    }
    first += dims[2];
    if (list && list->GetNumberOfIds() > 0 && local->GetNumberOfIds() == 0)
    {
      continue;
    }
    FramePlan plan;
    plan.Input = k;
    if (!MakePlan(input, local->GetNumberOfIds() ? local.Get() : nullptr, clipOrigin, clipSize, plan, error))
    {
      error = sweeps > 1 ? "sweep " + std::to_string(k) + ": " + error : error;
      return false;
    }
    plans.push_back(std::move(plan));
  }
  for (vtkIdType m = 0; list && m < list->GetNumberOfIds(); ++m)
  {
    if (list->GetId(m) < 0 || list->GetId(m) >= first)
    {
      error = "frame " + std::to_string(list->GetId(m)) + " of the frame list is outside the " + std::to_string(first) +
        " frames of the sequence" + (sweeps > 1 ? "s" : "");
      return false;
    }
  }
  if (plans.empty())
  {
    error = "input 0 must be a tracked frame sequence with pixels (W x H x N)";
    return false;
  }
  return true;
}

bool ComputeGrid(const std::vector<FramePlan>* plans, const double spacing[3], const double originSetting[3],
  const int extentSetting[6], vtkIdType maximumVoxels, double origin[3], int extent[6], std::string& error)
{
  for (int c = 0; c < 3; ++c)
  {
    if (!(spacing[c] > 0) || !std::isfinite(spacing[c]))
    {
      error = "OutputSpacing must be positive, not " + std::to_string(spacing[c]) + " on axis " + std::to_string(c);
      return false;
    }
  }
  const bool explicitOrigin = originSetting[0] != Unset && originSetting[1] != Unset && originSetting[2] != Unset;
  const bool explicitExtent = extentSetting[0] != UnsetExtent;
  double lo[3] = { VTK_DOUBLE_MAX, VTK_DOUBLE_MAX, VTK_DOUBLE_MAX };
  double hi[3] = { -VTK_DOUBLE_MAX, -VTK_DOUBLE_MAX, -VTK_DOUBLE_MAX };
  if (!explicitOrigin || !explicitExtent)
  {
    for (const FramePlan& plan : *plans)
    {
      for (const auto& m : plan.Poses)
      {
        for (int x : { plan.Clip[0], plan.Clip[1] })
        {
          for (int y : { plan.Clip[2], plan.Clip[3] })
          {
            for (int c = 0; c < 3; ++c)
            {
              const double p = m[4 * c] * x + m[4 * c + 1] * y + m[4 * c + 3];
              lo[c] = std::min(lo[c], p);
              hi[c] = std::max(hi[c], p);
            }
          }
        }
      }
    }
  }
  for (int c = 0; c < 3; ++c)
  {
    origin[c] = explicitOrigin ? originSetting[c] : lo[c];
    if (explicitExtent)
    {
      extent[2 * c] = extentSetting[2 * c];
      extent[2 * c + 1] = extentSetting[2 * c + 1];
    }
    else if (!explicitOrigin)
    {
      // vtkPlusVolumeReconstructor::SetOutputExtentFromFrameList (int(), as in the shipped reference).
      extent[2 * c] = 0;
      extent[2 * c + 1] = static_cast<int>((hi[c] - lo[c]) / spacing[c]);
    }
    else
    {
      // The voxels nearest the box's faces, with the insertion's rounding: every pixel lands.
      const double first = std::floor((lo[c] - origin[c]) / spacing[c] + 0.5);
      const double last = std::floor((hi[c] - origin[c]) / spacing[c] + 0.5);
      if (first < VTK_INT_MIN / 2 || last > VTK_INT_MAX / 2)
      {
        error = "the frames lie too far from OutputOrigin for an integer extent";
        return false;
      }
      extent[2 * c] = static_cast<int>(first);
      extent[2 * c + 1] = static_cast<int>(last);
    }
  }
  double voxels = 1;
  for (int c = 0; c < 3; ++c)
  {
    if (extent[2 * c + 1] < extent[2 * c])
    {
      std::ostringstream text;
      text << "the output grid is empty (extent " << extent[0] << " " << extent[1] << " " << extent[2] << " "
           << extent[3] << " " << extent[4] << " " << extent[5] << ")";
      error = text.str();
      return false;
    }
    voxels *= double(extent[2 * c + 1]) - extent[2 * c] + 1;
  }
  if (voxels > double(maximumVoxels))
  {
    std::ostringstream text;
    text << "the output grid would have " << voxels << " voxels (extent " << extent[0] << " " << extent[1] << " "
         << extent[2] << " " << extent[3] << " " << extent[4] << " " << extent[5] << "), more than "
         << "MaximumNumberOfVoxels = " << maximumVoxels << "; increase OutputSpacing or set a smaller OutputExtent";
    error = text.str();
    return false;
  }
  return true;
}
}

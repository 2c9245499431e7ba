#include "vtkUltrasoundVolumeCompounder.h"

#include "bigusGaussianFieldData.h"
#include "bigusPipeline.h"

#include "vtkAlgorithmOutput.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkSMPTools.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkUnsignedIntArray.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundVolumeCompounder);
vtkCxxSetObjectMacro(vtkUltrasoundVolumeCompounder, FrameList, vtkIdList);

namespace
{
constexpr double Unset = VTK_DOUBLE_MAX;
constexpr int UnsetExtent = VTK_INT_MIN;

/// The frames to insert, their poses and the inserted pixel range: what both RequestInformation
/// (automatic grid) and RequestData need.
struct FramePlan
{
  int Input = 0; // the sweep: connection of input ports 0 and 1
  int Width = 0;
  int Height = 0;
  int Frames = 0;                            // N of the sequence
  std::vector<vtkIdType> Inserted;           // sequence indices, in insertion order
  std::vector<std::array<double, 12>> Poses; // [Inserted.size()] first three rows of ImageToReference
  int Clip[4] = { 0, 0, 0, 0 };              // first and last column, first and last row (inclusive)
  std::vector<vtkIdType> SkippedInvalid;     // listed frames with FrameValid = 0
};

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

/// The plans of every sweep on input port 0 (@p list counts the sweeps' frames one sweep after the other;
/// a sweep none of whose frames is listed is left out). Errors name the sweep when there are several.
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

/// Output grid: explicit settings where given, otherwise PLUS's automatic grid from the frame corners.
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

/// Running state of one voxel grid while frames are inserted.
struct Accumulator
{
  int Dims[3];
  int Start[3]; // extent lower bounds
  double Origin[3];
  double Spacing[3];
  int Mode;
  float* Value;        // [voxels] sum (MEAN), maximum or latest value
  unsigned int* Count; // [voxels] pixels inserted
  vtkIdType Inserted = 0;

  /// Voxel index (or -1) of every pixel of the clip rectangle of one frame, row-major; masked-out
  /// pixels get -1 too.
  void Locate(const std::array<double, 12>& m, const int clip[4], const unsigned char* mask, int width,
    std::vector<vtkIdType>& target) const
  {
    const int columns = clip[1] - clip[0] + 1;
    const int rows = clip[3] - clip[2] + 1;
    target.resize(std::size_t(columns) * rows);
    vtkSMPTools::For(0, rows, 16, [&](vtkIdType rowBegin, vtkIdType rowEnd) {
      for (vtkIdType r = rowBegin; r < rowEnd; ++r)
      {
        const int y = clip[2] + static_cast<int>(r);
        vtkIdType* out = target.data() + r * columns;
        // Continuous voxel coordinates of pixel (x, y): start + x * step.
        double start[3], step[3];
        for (int c = 0; c < 3; ++c)
        {
          start[c] = (m[4 * c + 1] * y + m[4 * c + 3] - this->Origin[c]) / this->Spacing[c] - this->Start[c];
          step[c] = m[4 * c] / this->Spacing[c];
        }
        const unsigned char* maskRow = mask ? mask + std::size_t(y) * width : nullptr;
        for (int i = 0; i < columns; ++i)
        {
          const int x = clip[0] + i;
          if (maskRow && !maskRow[x])
          {
            out[i] = -1;
            continue;
          }
          vtkIdType index[3];
          bool inside = true;
          for (int c = 0; c < 3; ++c)
          {
            // Nearest voxel centre (vtkPlusPasteSliceIntoVolume's nearest-neighbour rounding).
            const double f = std::floor(start[c] + step[c] * x + 0.5);
            inside = inside && f >= 0 && f < this->Dims[c];
            index[c] = inside ? static_cast<vtkIdType>(f) : 0;
          }
          out[i] = inside ? index[0] + this->Dims[0] * (index[1] + vtkIdType(this->Dims[1]) * index[2]) : -1;
        }
      }
    });
  }

  /// Insert the pixels of one frame (typed pointer to its first pixel) at their voxels. Serial: many
  /// pixels share a voxel (several per voxel along each image axis), and the order matters for LATEST.
  template <typename T>
  void Insert(const T* frame, const int clip[4], int width, const std::vector<vtkIdType>& target)
  {
    const int columns = clip[1] - clip[0] + 1;
    const int rows = clip[3] - clip[2] + 1;
    for (int r = 0; r < rows; ++r)
    {
      const T* row = frame + std::size_t(clip[2] + r) * width + clip[0];
      const vtkIdType* voxel = target.data() + std::size_t(r) * columns;
      for (int i = 0; i < columns; ++i)
      {
        const vtkIdType v = voxel[i];
        if (v < 0)
        {
          continue;
        }
        const float value = static_cast<float>(row[i]);
        switch (this->Mode)
        {
          case vtkUltrasoundVolumeCompounder::MEAN:
            this->Value[v] += value;
            break;
          case vtkUltrasoundVolumeCompounder::MAXIMUM:
            this->Value[v] = this->Count[v] == 0 ? value : std::max(this->Value[v], value);
            break;
          default:
            this->Value[v] = value;
            break;
        }
        ++this->Count[v];
        ++this->Inserted;
      }
    }
  }
};

/// Gaussian hole filling as normalised convolution: for a cube of radius r, the Gaussian-weighted
/// mean of the inserted voxels is (G * (K V)) / (G * K) and the number of inserted voxels is B * K,
/// with K = 1 where a pixel was inserted, G the truncated Gaussian and B the box of the cube. Both
/// kernels are separable, so a cube costs 3 (2r + 1) operations per voxel and channel instead of
/// (2r + 1)^3, with the same result as visiting the cube voxel by voxel.
class HoleFiller
{
public:
  /// Per-thread buffers of one slab.
  struct SlabWork
  {
    std::vector<float> Sums;
    std::vector<float> Scratch;
    std::vector<float> Padded;
    std::vector<float> Line;
    std::vector<unsigned char> Rows;
  };

  HoleFiller(const int dims[3], float* value, const unsigned int* count)
    : Value(value)
    , Count(count)
  {
    std::copy(dims, dims + 3, this->Dims);
    const vtkIdType voxels = vtkIdType(dims[0]) * dims[1] * dims[2];
    this->State.assign(voxels, 0);
    this->RowHasKnown.assign(std::size_t(dims[1]) * dims[2], 0);
    vtkSMPTools::For(0, vtkIdType(dims[1]) * dims[2], 64, [&](vtkIdType begin, vtkIdType end) {
      for (vtkIdType row = begin; row < end; ++row)
      {
        const unsigned int* c = count + row * dims[0];
        unsigned char* s = this->State.data() + row * dims[0];
        for (int x = 0; x < dims[0]; ++x)
        {
          s[x] = c[x] > 0 ? 1 : 0;
          this->RowHasKnown[row] |= s[x];
        }
      }
    });
  }

  /// Fill the holes that a cube of radius r can fill; returns how many it filled.
  vtkIdType Pass(int radius, double sigma, double minimumKnownRatio)
  {
    std::vector<float> gauss(2 * radius + 1);
    for (int d = -radius; d <= radius; ++d)
    {
      gauss[d + radius] = static_cast<float>(std::exp(-0.5 * d * d / (sigma * sigma)));
    }
    const double side = 2.0 * radius + 1;
    const double needed = minimumKnownRatio * side * side * side;
    const int nz = this->Dims[2];
    std::vector<vtkIdType> filledPerSlice(nz, 0);
    // Slabs of at most this many slices bound the working memory whatever the SMP backend's chunks.
    const int slab = 8;
    vtkSMPTools::For(0, nz, slab, [&](vtkIdType zBegin, vtkIdType zEnd) {
      SlabWork work;
      for (vtkIdType z0 = zBegin; z0 < zEnd; z0 += slab)
      {
        const int z1 = static_cast<int>(std::min<vtkIdType>(zEnd, z0 + slab));
        this->Slab(static_cast<int>(z0), z1, radius, gauss, needed, work, filledPerSlice);
      }
    });
    vtkIdType filled = 0;
    for (vtkIdType f : filledPerSlice)
    {
      filled += f;
    }
    return filled;
  }

private:
  void Slab(int z0, int z1, int radius, const std::vector<float>& gauss, double needed, SlabWork& work,
    std::vector<vtkIdType>& filledPerSlice)
  {
    const int nx = this->Dims[0], ny = this->Dims[1], nz = this->Dims[2];
    const std::size_t plane = std::size_t(nx) * ny;
    const int zLo = std::max(0, z0 - radius);
    const int zHi = std::min(nz, z1 + radius);
    const int taps = 2 * radius + 1;
    const std::size_t slices = std::size_t(zHi - zLo);
    // Channels: 0 = sum of g K V, 1 = sum of g K, 2 = sum of K (the count).
    // work.Sums: [3, slices, ny, nx] after the x and y passes; work.Scratch: [3, ny, nx] after the x
    // pass of one slice; work.Rows: [slices, ny] 1 where a row of the slab's sums is non-zero.
    work.Sums.assign(3 * slices * plane, 0.0f);
    work.Scratch.resize(3 * plane);
    work.Rows.assign(slices * ny, 0);
    work.Padded.resize(2 * (std::size_t(nx) + 2 * radius));
    work.Line.resize(3 * std::size_t(nx));
    std::vector<unsigned char> scratchRows(ny);
    bool slabHasKnown = false;
    for (int z = zLo; z < zHi; ++z)
    {
      // x pass into the scratch slice (branch-free, zero-padded rows).
      bool any = false;
      for (int y = 0; y < ny; ++y)
      {
        const std::size_t row = std::size_t(z) * ny + y;
        scratchRows[y] = this->RowHasKnown[row];
        if (!scratchRows[y])
        {
          continue;
        }
        any = true;
        float* kv = work.Padded.data();
        float* k = kv + nx + 2 * radius;
        const unsigned int* known = this->Count + row * nx;
        const float* value = this->Value + row * nx;
        std::fill(kv, kv + radius, 0.0f);
        std::fill(k, k + radius, 0.0f);
        for (int x = 0; x < nx; ++x)
        {
          k[radius + x] = known[x] ? 1.0f : 0.0f;
          kv[radius + x] = known[x] ? value[x] : 0.0f;
        }
        std::fill(kv + radius + nx, kv + nx + 2 * radius, 0.0f);
        std::fill(k + radius + nx, k + nx + 2 * radius, 0.0f);
        float* a = work.Scratch.data() + std::size_t(y) * nx;
        float* b = a + plane;
        float* c = b + plane;
        std::fill(a, a + nx, 0.0f);
        std::fill(b, b + nx, 0.0f);
        std::fill(c, c + nx, 0.0f);
        for (int d = 0; d < taps; ++d)
        {
          const float g = gauss[d];
          const float* kvd = kv + d;
          const float* kd = k + d;
          for (int x = 0; x < nx; ++x)
          {
            a[x] += g * kvd[x];
            b[x] += g * kd[x];
            c[x] += kd[x];
          }
        }
      }
      if (!any)
      {
        continue;
      }
      slabHasKnown = true;
      // y pass into the slab; output rows with no non-zero input row within the radius stay zero.
      const std::size_t offset = std::size_t(z - zLo) * plane;
      for (int y = 0; y < ny; ++y)
      {
        const int d0 = std::max(-radius, -y), d1 = std::min(radius, ny - 1 - y);
        bool near = false;
        for (int d = d0; d <= d1 && !near; ++d)
        {
          near = scratchRows[y + d] != 0;
        }
        if (!near)
        {
          continue;
        }
        work.Rows[std::size_t(z - zLo) * ny + y] = 1;
        for (int ch = 0; ch < 3; ++ch)
        {
          float* out = work.Sums.data() + ch * slices * plane + offset + std::size_t(y) * nx;
          for (int d = d0; d <= d1; ++d)
          {
            if (!scratchRows[y + d])
            {
              continue;
            }
            const float g = ch == 2 ? 1.0f : gauss[d + radius];
            const float* in = work.Scratch.data() + ch * plane + std::size_t(y + d) * nx;
            for (int x = 0; x < nx; ++x)
            {
              out[x] += g * in[x];
            }
          }
        }
      }
    }
    if (!slabHasKnown)
    {
      return;
    }
    // z pass, row by row, for the rows that have holes and non-zero sums within the radius; fills in
    // place (only inserted voxels are ever read as values).
    for (int z = z0; z < z1; ++z)
    {
      const int d0 = std::max(-radius, -z), d1 = std::min(radius, nz - 1 - z);
      vtkIdType filled = 0;
      for (int y = 0; y < ny; ++y)
      {
        bool near = false;
        for (int d = d0; d <= d1 && !near; ++d)
        {
          near = work.Rows[std::size_t(z + d - zLo) * ny + y] != 0;
        }
        if (!near)
        {
          continue;
        }
        const std::size_t rowStart = std::size_t(z) * plane + std::size_t(y) * nx;
        const unsigned char* state = this->State.data() + rowStart;
        float* sa = work.Line.data();
        float* sb = sa + nx;
        float* sc = sb + nx;
        std::fill(sa, sa + 3 * nx, 0.0f);
        for (int d = d0; d <= d1; ++d)
        {
          if (!work.Rows[std::size_t(z + d - zLo) * ny + y])
          {
            continue;
          }
          const float g = gauss[d + radius];
          const std::size_t at = std::size_t(z + d - zLo) * plane + std::size_t(y) * nx;
          const float* a = work.Sums.data() + at;
          const float* b = a + slices * plane;
          const float* c = b + slices * plane;
          for (int x = 0; x < nx; ++x)
          {
            sa[x] += g * a[x];
            sb[x] += g * b[x];
            sc[x] += c[x];
          }
        }
        for (int x = 0; x < nx; ++x)
        {
          // sc holds a small integer count, exact in float.
          if (!state[x] && sc[x] > 0 && sc[x] > needed && sb[x] > 0)
          {
            this->Value[rowStart + x] = sa[x] / sb[x];
            this->State[rowStart + x] = 1;
            ++filled;
          }
        }
      }
      filledPerSlice[z] = filled;
    }
  }

  int Dims[3];
  float* Value;
  const unsigned int* Count;
  std::vector<unsigned char> State;       // [voxels] 1 = inserted or already filled
  std::vector<unsigned char> RowHasKnown; // [nz * ny] rows with an inserted voxel
};
}

vtkUltrasoundVolumeCompounder::vtkUltrasoundVolumeCompounder()
{
  this->SetNumberOfInputPorts(2);
  this->SetOutputOriginToDefault();
  this->SetOutputExtentToDefault();
}

vtkUltrasoundVolumeCompounder::~vtkUltrasoundVolumeCompounder()
{
  this->SetFrameList(nullptr);
}

vtkMTimeType vtkUltrasoundVolumeCompounder::GetMTime()
{
  vtkMTimeType time = this->Superclass::GetMTime();
  if (this->FrameList)
  {
    time = std::max(time, this->FrameList->GetMTime());
  }
  return time;
}

void vtkUltrasoundVolumeCompounder::SetOutputOriginToDefault()
{
  this->SetOutputOrigin(Unset, Unset, Unset);
}

void vtkUltrasoundVolumeCompounder::SetOutputExtentToDefault()
{
  this->SetOutputExtent(UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent);
}

const char* vtkUltrasoundVolumeCompounder::GetCompoundingModeAsString()
{
  switch (this->CompoundingMode)
  {
    case MAXIMUM:
      return "MAXIMUM";
    case LATEST:
      return "LATEST";
    default:
      return "MEAN";
  }
}

int vtkUltrasoundVolumeCompounder::FillInputPortInformation(int port, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  info->Set(vtkAlgorithm::INPUT_IS_REPEATABLE(), 1);
  if (port == 1)
  {
    info->Set(vtkAlgorithm::INPUT_IS_OPTIONAL(), 1);
  }
  return 1;
}

int vtkUltrasoundVolumeCompounder::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  const bool explicitGrid = this->OutputOrigin[0] != Unset && this->OutputOrigin[1] != Unset &&
    this->OutputOrigin[2] != Unset && this->OutputExtent[0] != UnsetExtent;
  std::vector<FramePlan> plans;
  std::string error;
  if (!explicitGrid)
  {
    // The automatic grid comes from the poses: bring the sequences up to date now.
    for (int k = 0; k < this->GetNumberOfInputConnections(0); ++k)
    {
      this->GetInputConnection(0, k)->GetProducer()->UpdatePiece(0, 1, 0);
    }
    if (!MakePlans(inputVector[0], this->FrameList, this->ClipRectangleOrigin, this->ClipRectangleSize, plans, error))
    {
      vtkErrorMacro(<< error);
      return 0;
    }
  }
  double origin[3];
  int extent[6];
  if (!ComputeGrid(explicitGrid ? nullptr : &plans, this->OutputSpacing, this->OutputOrigin, this->OutputExtent,
        this->MaximumNumberOfVoxels, origin, extent, error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  outInfo->Set(vtkDataObject::SPACING(), this->OutputSpacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, VTK_FLOAT, 1);
  return 1;
}

int vtkUltrasoundVolumeCompounder::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // Every frame and the whole mask are needed, whatever part of the volume is asked for.
  bigus::RequestWholeExtent(inputVector, 2);
  return 1;
}

int vtkUltrasoundVolumeCompounder::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  this->NumberOfInsertedFrames = 0;
  this->NumberOfInsertedPixels = 0;
  this->NumberOfHitVoxels = 0;
  this->NumberOfFilledVoxels = 0;
  this->InsertionSeconds = 0;
  this->HoleFillingSeconds = 0;

  std::vector<FramePlan> plans;
  std::string error;
  double origin[3];
  int extent[6];
  const int sweeps = inputVector[0]->GetNumberOfInformationObjects();
  const int maskCount = inputVector[1]->GetNumberOfInformationObjects();
  if (!bigus::CheckMaskCount(maskCount, sweeps, &error) ||
    !MakePlans(inputVector[0], this->FrameList, this->ClipRectangleOrigin, this->ClipRectangleSize, plans, error) ||
    !ComputeGrid(&plans, this->OutputSpacing, this->OutputOrigin, this->OutputExtent, this->MaximumNumberOfVoxels,
      origin, extent, error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  for (const FramePlan& plan : plans)
  {
    if (!plan.SkippedInvalid.empty())
    {
      vtkWarningMacro(<< (sweeps > 1 ? "sweep " + std::to_string(plan.Input) + ": " : std::string())
                      << plan.SkippedInvalid.size() << " listed frame(s) have FrameValid = 0 and are not inserted "
                      << "(first: frame " << plan.SkippedInvalid.front() << ")");
    }
  }

  output->SetExtent(extent);
  output->SetOrigin(origin);
  output->SetSpacing(this->OutputSpacing);
  const vtkIdType voxels =
    vtkIdType(extent[1] - extent[0] + 1) * (extent[3] - extent[2] + 1) * (extent[5] - extent[4] + 1);
  vtkNew<vtkFloatArray> values;
  values->SetName("Intensity");
  vtkNew<vtkUnsignedIntArray> counts;
  counts->SetName("InsertedPixelCount");
  values->SetNumberOfTuples(voxels);
  counts->SetNumberOfTuples(voxels);
  vtkSMPTools::Fill(values->GetPointer(0), values->GetPointer(0) + voxels, 0.0f);
  vtkSMPTools::Fill(counts->GetPointer(0), counts->GetPointer(0) + voxels, 0u);

  Accumulator acc;
  for (int c = 0; c < 3; ++c)
  {
    acc.Dims[c] = extent[2 * c + 1] - extent[2 * c] + 1;
    acc.Start[c] = extent[2 * c];
    acc.Origin[c] = origin[c];
    acc.Spacing[c] = this->OutputSpacing[c];
  }
  acc.Mode = this->CompoundingMode;
  acc.Value = values->GetPointer(0);
  acc.Count = counts->GetPointer(0);

  const auto start = std::chrono::steady_clock::now();
  const double insertionShare = this->FillHoles ? 0.5 : 1.0;
  std::size_t total = 0, done = 0;
  for (const FramePlan& plan : plans)
  {
    total += plan.Inserted.size();
  }
  std::vector<vtkIdType> target;
  for (const FramePlan& plan : plans)
  {
    vtkImageData* input = vtkImageData::GetData(inputVector[0], plan.Input);
    vtkImageData* maskImage = maskCount ? vtkImageData::GetData(inputVector[1], plan.Input) : nullptr;
    // The fan mask, as bytes: one W x H plane shared by every frame, or one per frame.
    const std::size_t framePixels = std::size_t(plan.Width) * plan.Height;
    std::vector<unsigned char> mask;
    bool maskPerFrame = false;
    if (maskImage)
    {
      int maskDims[3];
      maskImage->GetDimensions(maskDims);
      vtkDataArray* maskScalars = maskImage->GetPointData()->GetScalars();
      const bool sizeOk =
        maskDims[0] == plan.Width && maskDims[1] == plan.Height && (maskDims[2] == 1 || maskDims[2] == plan.Frames);
      if (!maskScalars || maskScalars->GetNumberOfComponents() != 1 || !sizeOk ||
        maskScalars->GetNumberOfTuples() != vtkIdType(framePixels) * maskDims[2])
      {
        vtkErrorMacro(<< (sweeps > 1 ? "sweep " + std::to_string(plan.Input) + ": " : std::string())
                      << "the fan mask must be a one-component W x H x 1 or W x H x N image for the " << plan.Width
                      << " x " << plan.Height << " x " << plan.Frames << " sequence, not " << maskDims[0] << " x "
                      << maskDims[1] << " x " << maskDims[2]);
        output->Initialize();
        return 0;
      }
      maskPerFrame = maskDims[2] > 1;
      mask.resize(maskScalars->GetNumberOfTuples());
      vtkSMPTools::For(0, maskScalars->GetNumberOfTuples(), 65536, [&](vtkIdType begin, vtkIdType end) {
        for (vtkIdType p = begin; p < end; ++p)
        {
          mask[p] = maskScalars->GetComponent(p, 0) != 0 ? 1 : 0;
        }
      });
    }
    void* pixels = input->GetScalarPointer();
    const int scalarType = input->GetScalarType();
    for (std::size_t k = 0; k < plan.Inserted.size(); ++k)
    {
      const vtkIdType f = plan.Inserted[k];
      const unsigned char* frameMask =
        mask.empty() ? nullptr : mask.data() + (maskPerFrame ? std::size_t(f) * framePixels : 0);
      acc.Locate(plan.Poses[k], plan.Clip, frameMask, plan.Width, target);
      switch (scalarType)
      {
        vtkTemplateMacro(
          acc.Insert(static_cast<const VTK_TT*>(pixels) + std::size_t(f) * framePixels, plan.Clip, plan.Width, target));
        default:
          vtkErrorMacro("unsupported scalar type " << input->GetScalarTypeAsString());
          output->Initialize();
          return 0;
      }
      this->UpdateProgress(insertionShare * ++done / total);
      if (this->AbortExecute)
      {
        output->Initialize();
        return 0;
      }
    }
  }
  float* value = acc.Value;
  const unsigned int* count = acc.Count;
  const bool mean = this->CompoundingMode == MEAN;
  std::vector<vtkIdType> hitPerChunk;
  {
    const vtkIdType chunk = 1 << 20;
    hitPerChunk.assign((voxels + chunk - 1) / chunk, 0);
    vtkSMPTools::For(0, vtkIdType(hitPerChunk.size()), 1, [&](vtkIdType begin, vtkIdType end) {
      for (vtkIdType c = begin; c < end; ++c)
      {
        vtkIdType hit = 0;
        for (vtkIdType v = c * chunk; v < std::min(voxels, (c + 1) * chunk); ++v)
        {
          if (count[v])
          {
            ++hit;
            if (mean)
            {
              value[v] /= count[v];
            }
          }
        }
        hitPerChunk[c] = hit;
      }
    });
  }
  for (vtkIdType hit : hitPerChunk)
  {
    this->NumberOfHitVoxels += hit;
  }
  this->NumberOfInsertedFrames = static_cast<int>(total);
  this->NumberOfInsertedPixels = acc.Inserted;
  const auto inserted = std::chrono::steady_clock::now();
  this->InsertionSeconds = std::chrono::duration<double>(inserted - start).count();

  if (this->FillHoles)
  {
    HoleFiller filler(acc.Dims, value, count);
    const int radii = (this->HoleFillingMaximumKernelSize - 1) / 2;
    for (int r = 1; r <= radii; ++r)
    {
      this->NumberOfFilledVoxels += filler.Pass(r, this->HoleFillingSigma * r, this->HoleFillingMinimumKnownRatio);
      this->UpdateProgress(insertionShare + (1 - insertionShare) * r / radii);
      if (this->AbortExecute)
      {
        output->Initialize();
        return 0;
      }
    }
    this->HoleFillingSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - inserted).count();
  }

  output->GetPointData()->SetScalars(values);
  output->GetPointData()->AddArray(counts);
  return 1;
}

void vtkUltrasoundVolumeCompounder::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FrameList: ";
  if (this->FrameList && this->FrameList->GetNumberOfIds() > 0)
  {
    os << this->FrameList->GetNumberOfIds() << " frames\n";
  }
  else
  {
    os << "(all frames)\n";
  }
  os << indent << "OutputSpacing: " << this->OutputSpacing[0] << " " << this->OutputSpacing[1] << " "
     << this->OutputSpacing[2] << "\n";
  os << indent << "OutputOrigin: ";
  if (this->OutputOrigin[0] == Unset)
  {
    os << "(automatic)\n";
  }
  else
  {
    os << this->OutputOrigin[0] << " " << this->OutputOrigin[1] << " " << this->OutputOrigin[2] << "\n";
  }
  os << indent << "OutputExtent: ";
  if (this->OutputExtent[0] == UnsetExtent)
  {
    os << "(automatic)\n";
  }
  else
  {
    for (int e = 0; e < 6; ++e)
    {
      os << this->OutputExtent[e] << (e < 5 ? " " : "\n");
    }
  }
  os << indent << "ClipRectangleOrigin: " << this->ClipRectangleOrigin[0] << " " << this->ClipRectangleOrigin[1]
     << "\n";
  os << indent << "ClipRectangleSize: " << this->ClipRectangleSize[0] << " " << this->ClipRectangleSize[1] << "\n";
  os << indent << "CompoundingMode: " << this->GetCompoundingModeAsString() << "\n";
  os << indent << "FillHoles: " << (this->FillHoles ? "On" : "Off") << "\n";
  os << indent << "HoleFillingMaximumKernelSize: " << this->HoleFillingMaximumKernelSize << "\n";
  os << indent << "HoleFillingSigma: " << this->HoleFillingSigma << "\n";
  os << indent << "HoleFillingMinimumKnownRatio: " << this->HoleFillingMinimumKnownRatio << "\n";
  os << indent << "MaximumNumberOfVoxels: " << this->MaximumNumberOfVoxels << "\n";
  os << indent << "NumberOfInsertedFrames: " << this->NumberOfInsertedFrames << "\n";
  os << indent << "NumberOfInsertedPixels: " << this->NumberOfInsertedPixels << "\n";
  os << indent << "NumberOfHitVoxels: " << this->NumberOfHitVoxels << "\n";
  os << indent << "NumberOfFilledVoxels: " << this->NumberOfFilledVoxels << "\n";
  os << indent << "InsertionSeconds: " << this->InsertionSeconds << "\n";
  os << indent << "HoleFillingSeconds: " << this->HoleFillingSeconds << "\n";
}

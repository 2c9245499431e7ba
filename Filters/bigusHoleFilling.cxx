// vtkUltrasoundVolumeCompounder's Gaussian hole filling (PLUS's GAUSSIAN element) as normalised convolution.
#include "bigusVolumeCompounding.h"

#include "vtkSMPTools.h"

#include <algorithm>
#include <cmath>

namespace bigus::compounding
{
HoleFiller::HoleFiller(const int dims[3], float* value, const unsigned int* count)
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

vtkIdType HoleFiller::Pass(int radius, double sigma, double minimumKnownRatio)
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

void HoleFiller::Slab(int z0, int z1, int radius, const std::vector<float>& gauss, double needed, SlabWork& work,
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
}

/**
 * @file    bigusVolumeCompounding.h
 * @brief   The parts of vtkUltrasoundVolumeCompounder (private, not wrapped): the frame plans and the
 *          output grid (bigusCompoundingGrid.cxx), and the Gaussian hole filling (bigusHoleFilling.cxx).
 *          The conventions are PLUS's, as the class description of vtkUltrasoundVolumeCompounder gives them.
 */
#ifndef bigusVolumeCompounding_h
#define bigusVolumeCompounding_h

#include "vtkType.h"

#include <array>
#include <string>
#include <vector>

class vtkIdList;
class vtkInformationVector;

namespace bigus::compounding
{
/// OutputOrigin and OutputExtent values that mean "automatic".
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

/// The plans of every sweep on input port 0 (@p list counts the sweeps' frames one sweep after the other;
/// a sweep none of whose frames is listed is left out). Errors name the sweep when there are several.
bool MakePlans(vtkInformationVector* inputs, vtkIdList* list, const int clipOrigin[2], const int clipSize[2],
  std::vector<FramePlan>& plans, std::string& error);

/// Output grid: explicit settings where given, otherwise PLUS's automatic grid from the frame corners.
bool ComputeGrid(const std::vector<FramePlan>* plans, const double spacing[3], const double originSetting[3],
  const int extentSetting[6], vtkIdType maximumVoxels, double origin[3], int extent[6], std::string& error);

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

  /// The grid of @p dims voxels: @p value its compounded values (holes filled in place), @p count the pixels
  /// inserted into each voxel.
  HoleFiller(const int dims[3], float* value, const unsigned int* count);

  /// Fill the holes that a cube of radius r can fill; returns how many it filled.
  vtkIdType Pass(int radius, double sigma, double minimumKnownRatio);

private:
  void Slab(int z0, int z1, int radius, const std::vector<float>& gauss, double needed, SlabWork& work,
    std::vector<vtkIdType>& filledPerSlice);

  int Dims[3];
  float* Value;
  const unsigned int* Count;
  std::vector<unsigned char> State;       // [voxels] 1 = inserted or already filled
  std::vector<unsigned char> RowHasKnown; // [nz * ny] rows with an inserted voxel
};
}

#endif

/**
 * @class   vtkUltrasoundVolumeSweep
 * @brief   Synthetic tracked sweep through a known 3D volume with exact poses: the volume protocol
 *          (train on parallel slices of a volume, test on unseen slices).
 *
 * Input port 0: a 3D volume (`vtkImageData`, one scalar component, at least 2 voxels and a positive
 * spacing along every axis, mm). Output port 0: a tracked frame sequence W x H x N (DESIGN section 2;
 * scalars "Intensity", float by default, unsigned char volumes divided by 255; ImageToReference,
 * Timestamp = k * 0.05 s, FrameValid = 1, FrameIndex = k). Output port 1: the per-frame mask, a
 * W x H x N unsigned char image with scalars "FanMask" (1 where the frame samples the volume's data).
 * Both come from an internal vtkUltrasoundSequenceReslice (trilinear by default; Border on, so the
 * volume reaches half a voxel beyond its first and last voxel centres), whose class description
 * defines the sampling and the mask exactly.
 *
 * Geometry. Let o, s, d be the volume's origin, spacing (mm) and dimensions (voxels) and e_0, e_1, e_2
 * its axes (the columns of its direction matrix). For a sweep axis a:
 * - normal n = e_a, columns u = e_((a+1)%3), rows v = e_((a+2)%3) (cyclic, so u x v = n);
 * - pixel spacings p_u = p_v = PixelSpacing, or s_u and s_v when PixelSpacing is 0 (default);
 * - frame size W = floor((d_u - 1) s_u / p_u) + 1, H = floor((d_v - 1) s_v / p_v) + 1: the voxel
 *   centres of the cross-section, centred on it (W = d_u, H = d_v by default);
 * - c = the volume centre o + sum_b ((d_b - 1) s_b / 2) e_b; L = (d_a - 1) s_a, the distance from the
 *   first to the last voxel plane along n;
 * - frame k has a position z_k in [0, L] (mm from the first voxel plane) and a rotation R_k, and
 *   pixel (i, j) lies at (ImageToReference_k, pixel centres)
 *       x_k(i, j) = c + (z_k - L / 2) n + R_k [ (i - (W - 1) / 2) p_u u + (j - (H - 1) / 2) p_v v ],
 *   i.e. ImageToReference_k has the columns p_u R_k u, p_v R_k v, R_k n and the translation
 *   c + (z_k - L / 2) n - R_k [ (W - 1) / 2 p_u u + (H - 1) / 2 p_v v ].
 *
 * Protocols:
 * - Parallel (default): axis a = SweepAxis, R_k = I, z_k = (k + Offset) * Delta with the slice spacing
 *   Delta = d_a s_a / N (d_a voxels of thickness s_a shared by N slices). Offset 0 puts slice 0 on the
 *   first voxel plane, and with N = d_a every slice on a voxel plane (the volume is reproduced);
 *   N = d_a / 2 gives the even voxel planes and, with Offset 0.5, the odd ones. Offset 0.5 slices lie
 *   exactly midway between consecutive Offset 0 slices of the same N. All slices lie within the
 *   volume (with its half-voxel border) while N <= 2 d_a (1 - Offset): N <= 2 d_a for Offset 0,
 *   N <= d_a for Offset 0.5; a slice beyond it is entirely masked.
 * - Orthogonal: the Parallel sweep along the next axis, a = (SweepAxis + 1) % 3 (SweepAxis 2, the
 *   default: slices step along x and span y (columns) and z (rows)); the frame size is that of the
 *   other cross-section.
 * - Oblique: axis a = SweepAxis and the Parallel frame size; for each k in turn three uniform draws
 *   U1, U2, U3 in [0, 1) give z_k = U1 L, the tilt axis w_k = cos(phi_k) u + sin(phi_k) v with
 *   phi_k = 2 pi U2 and the tilt angle theta_k = MaximumTiltAngle * U3; R_k is the rotation by
 *   theta_k about w_k, so the angle between the slice normal R_k n and n is theta_k. The frames are
 *   then ordered by z_k (a sweep, not a shuffle). Corners of a tilted frame leave the volume; the mask
 *   says where. Uniform draws are (x >> 11) * 2^-53 of std::mt19937_64 seeded with Seed, so a seed
 *   gives the same poses with every standard library. Offset is not used.
 *
 * Errors (vtkErrorMacro, the request fails, empty outputs): a volume that is not 3D, has a spacing
 * <= 0 or no one-component scalars, NumberOfFrames < 1, Offset outside [0, 1), MaximumTiltAngle
 * outside [0, 90] degrees, a SweepAxis or Protocol out of range, PixelSpacing < 0 or so small that a
 * frame would exceed 16384 pixels a side.
 */
#ifndef vtkUltrasoundVolumeSweep_h
#define vtkUltrasoundVolumeSweep_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

class BIGUSFILTERS_EXPORT vtkUltrasoundVolumeSweep : public vtkImageAlgorithm
{
public:
  static vtkUltrasoundVolumeSweep* New();
  vtkTypeMacro(vtkUltrasoundVolumeSweep, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// The W x H x N "FanMask" sequence (output port 1).
  vtkImageData* GetMaskOutput();
  vtkAlgorithmOutput* GetMaskOutputPort() { return this->GetOutputPort(1); }

  enum Protocols
  {
    PARALLEL = 0,
    OBLIQUE = 1,
    ORTHOGONAL = 2
  };
  ///@{ Sweep protocol (default Parallel; see the class description).
  vtkSetMacro(Protocol, int);
  vtkGetMacro(Protocol, int);
  void SetProtocolToParallel() { this->SetProtocol(PARALLEL); }
  void SetProtocolToOblique() { this->SetProtocol(OBLIQUE); }
  void SetProtocolToOrthogonal() { this->SetProtocol(ORTHOGONAL); }
  ///@}

  /// Volume axis (0, 1, 2) the parallel slices step along (default 2).
  vtkSetMacro(SweepAxis, int);
  vtkGetMacro(SweepAxis, int);

  /// Number of frames N (default 160; the paper uses 160 and 80).
  vtkSetMacro(NumberOfFrames, int);
  vtkGetMacro(NumberOfFrames, int);

  /// Shift of the parallel slices as a fraction of the slice spacing, in [0, 1): 0 for the training
  /// sweep, 0.5 for the in-between test sweep (default 0).
  vtkSetMacro(Offset, double);
  vtkGetMacro(Offset, double);

  /// Largest tilt (degrees, [0, 90]) of an Oblique frame's normal from the sweep axis (default 30).
  vtkSetMacro(MaximumTiltAngle, double);
  vtkGetMacro(MaximumTiltAngle, double);

  /// Seed of the Oblique poses (default 1).
  vtkSetMacro(Seed, unsigned int);
  vtkGetMacro(Seed, unsigned int);

  /// Pixel spacing (mm) of the frames; 0 (default) = the volume's spacing along u and v.
  vtkSetMacro(PixelSpacing, double);
  vtkGetMacro(PixelSpacing, double);

  ///@{ Sampling settings passed to the internal vtkUltrasoundSequenceReslice.
  vtkSetClampMacro(InterpolationMode, int, 0, 1);
  vtkGetMacro(InterpolationMode, int);
  void SetInterpolationModeToNearestNeighbor() { this->SetInterpolationMode(0); }
  void SetInterpolationModeToLinear() { this->SetInterpolationMode(1); }
  vtkSetMacro(MaskEmptyVoxels, bool);
  vtkGetMacro(MaskEmptyVoxels, bool);
  vtkBooleanMacro(MaskEmptyVoxels, bool);
  vtkSetMacro(OutputScalarType, int);
  vtkGetMacro(OutputScalarType, int);
  void SetOutputScalarTypeToFloat() { this->SetOutputScalarType(VTK_FLOAT); }
  void SetOutputScalarTypeToUnsignedChar() { this->SetOutputScalarType(VTK_UNSIGNED_CHAR); }
  ///@}

  ///@{ Geometry of the last UpdateInformation(): frame size W x H (pixels) and, for Parallel and
  /// Orthogonal, the slice spacing Delta (mm; 0 for Oblique).
  vtkGetVector2Macro(FrameSize, int);
  vtkGetMacro(SliceSpacing, double);
  ///@}

  /// Seconds spent in the last RequestData (poses and sampling).
  vtkGetMacro(SecondsToBuild, double);

protected:
  vtkUltrasoundVolumeSweep();
  ~vtkUltrasoundVolumeSweep() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  int Protocol = PARALLEL;
  int SweepAxis = 2;
  int NumberOfFrames = 160;
  double Offset = 0.0;
  double MaximumTiltAngle = 30.0;
  unsigned int Seed = 1;
  double PixelSpacing = 0.0;
  int InterpolationMode = 1;
  bool MaskEmptyVoxels = true;
  int OutputScalarType = VTK_FLOAT;
  int FrameSize[2] = { 0, 0 };
  double SliceSpacing = 0.0;
  double SecondsToBuild = 0.0;

private:
  vtkUltrasoundVolumeSweep(const vtkUltrasoundVolumeSweep&) = delete;
  void operator=(const vtkUltrasoundVolumeSweep&) = delete;
};

#endif

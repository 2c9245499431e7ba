/**
 * @class   vtkUltrasoundVolumeCompounder
 * @brief   Classical volume compounding of a tracked freehand sweep (the PLUS volume reconstruction
 *          baseline): pixel nearest-neighbour insertion, MEAN / MAXIMUM / LATEST compounding and
 *          Gaussian hole filling.
 *
 * Inputs:
 * - port 0: a tracked frame sequence (DESIGN section 2): W x H x N `vtkImageData`, one-component
 *   scalars (any type), field data `ImageToReference` (N tuples of 16 doubles, row-major, maps pixel
 *   (column, row, 0, 1) to mm) and, when present, `FrameValid`;
 * - port 1, optional: the fan mask, W x H x 1 (one mask for all frames, e.g. vtkUltrasoundFanMask's
 *   `FanMask`) or W x H x N (mask k belongs to frame k); non-zero = imaged pixel
 *   (SetFanMaskConnection / SetFanMaskData). Without it every pixel is inserted, as PLUS does.
 *
 * Several sweeps of one region (AddInputConnection on port 0, as vtkAppendFilter takes them; each with its own
 * frame size) are compounded into one volume, the automatic grid covering all of them: frames are inserted
 * sweep after sweep, and the frame list counts the sweeps' frames one sweep after the other (as
 * vtkGaussianFieldTrainer's frame indices do). Port 1 then has no mask or one per sweep, in their order;
 * errors name the sweep.
 *
 * Output: a `vtkImageData` volume in the reference frame (axis-aligned, mm): voxel (i, j, k) is centred
 * at OutputOrigin + (i, j, k) * OutputSpacing. Point data:
 * - `Intensity` (active scalars, float): the compounded value in the input's intensity units, 0 where
 *   no pixel landed and no hole was filled;
 * - `InsertedPixelCount` (unsigned int): how many pixels were inserted into the voxel (0 for empty and
 *   for hole-filled voxels, so the two kinds of voxel can be told apart).
 *
 * Frames: those of SetFrameList (indices into the sequence; this is how a hold-out protocol keeps its
 * held-out frames out), default every frame; frames whose `FrameValid` is 0 are skipped with a warning
 * (PLUS skips them too). A frame listed twice is inserted twice.
 *
 * Conventions, all those of the PLUS toolkit (vtkPlusVolumeReconstructor, vtkPlusPasteSliceIntoVolume,
 * vtkPlusFillHolesInVolume; https://plustoolkit.github.io), so that this filter reproduces PLUS's
 * reconstructions of the same sweep:
 * - Clip rectangle (pixels; used when both sizes are positive): columns max(0, x0) .. min(W - 1,
 *   x0 + width) and rows max(0, y0) .. min(H - 1, y0 + height), both ends included.
 * - Automatic grid: the bounding box (mm) of the four clip-rectangle corners of every inserted frame;
 *   origin = the box's lower corner, extent = 0 .. int((max - min) / spacing) per axis (the older PLUS
 *   rule, which SpinePhantomFreehandReconstructed.mha follows; recent PLUS versions round up). Like
 *   PLUS, this drops the pixels within the last half voxel below the box's upper faces (260 of the
 *   spine phantom's 10.6 million). With an explicit OutputOrigin and no explicit extent, the extent
 *   runs over the voxels nearest the box's faces, round((min - origin) / spacing) ..
 *   round((max - origin) / spacing), so that every pixel lands. An explicit OutputExtent is used as
 *   given. The grid needs the poses, so the input is brought up to date in RequestInformation when a
 *   default is in use.
 * - Insertion: pixel nearest neighbour. Each pixel goes to the voxel nearest its mm position (index
 *   floor((p - origin) / spacing + 0.5)); pixels that land outside the grid are dropped.
 * - Compounding: MEAN (default; the mean of the pixels inserted into the voxel), MAXIMUM, or LATEST
 *   (the last inserted pixel, in frame-list order, then row-major pixel order).
 * - Hole filling (FillHoles, default on): PLUS's GAUSSIAN hole filling element, applied as its element
 *   list is (kernels of increasing size, each tried on the holes the previous ones left). A voxel with
 *   no inserted pixel gets the Gaussian-weighted mean of the inserted (never of the filled) voxels in a
 *   cube of (2r + 1)^3 voxels around it, weights exp(-d^2 / (2 sigma^2)) with d in voxels, provided the
 *   fraction of inserted voxels in the cube exceeds HoleFillingMinimumKnownRatio. Cubes of radius
 *   r = 1, 2, ..., (HoleFillingMaximumKernelSize - 1) / 2 are tried in turn, with sigma =
 *   HoleFillingSigma * r. Defaults: kernels 3^3, 5^3 and 7^3, sigma 1, 2 and 3 voxels, known
 *   ratio 0.25 (see the setters for why). PLUS's own spine-phantom configuration used STICK filling
 *   (sticks of up to 9 voxels); these defaults were chosen as the kernel sizes and ratio whose result
 *   agrees best with that reconstruction (Testing/Cxx/TestUltrasoundVolumeCompounder.cxx; the agreement:
 *   docs/FINDINGS.md, "The trainer's defaults, measured").
 *
 * Multi-threaded with vtkSMPTools (pixel positions of a frame, hole filling); the result does not
 * depend on the number of threads. Progress is reported per frame and per hole-filling kernel, and
 * AbortExecute is honoured between them.
 *
 * Errors fail the request with vtkErrorMacro and an empty output, never a crash: no input or empty
 * frames, scalars with more than one component, no `ImageToReference` or one with the wrong number of
 * tuples or components, a frame index outside the sequence, a non-finite, singular (image axes of zero
 * length or parallel) or non-affine pose of an inserted frame, no valid frame to insert, a clip
 * rectangle outside the image, a mask that is not W x H x 1 or W x H x N, a non-positive spacing,
 * an empty grid, or a grid of more than MaximumNumberOfVoxels voxels.
 */
#ifndef vtkUltrasoundVolumeCompounder_h
#define vtkUltrasoundVolumeCompounder_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

class vtkIdList;

class BIGUSFILTERS_EXPORT vtkUltrasoundVolumeCompounder : public vtkImageAlgorithm
{
public:
  static vtkUltrasoundVolumeCompounder* New();
  vtkTypeMacro(vtkUltrasoundVolumeCompounder, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// Fan mask (W x H x 1 or W x H x N, non-zero = imaged) on the optional input port 1.
  void SetFanMaskConnection(vtkAlgorithmOutput* output) { this->SetInputConnection(1, output); }
  void SetFanMaskData(vtkDataObject* mask) { this->SetInputData(1, mask); }
  /// Disconnect every sweep (port 0), or every fan mask (port 1): the ParaView proxy's clean commands.
  void RemoveAllSweepConnections() { this->RemoveAllInputConnections(0); }
  void RemoveAllFanMaskConnections() { this->RemoveAllInputConnections(1); }

  ///@{ Frames to insert (indices into the sequence); nullptr or empty = every frame.
  void SetFrameList(vtkIdList* frames);
  vtkGetObjectMacro(FrameList, vtkIdList);
  ///@}

  ///@{ Voxel size (mm), each positive. Default 0.5 0.5 0.5.
  vtkSetVector3Macro(OutputSpacing, double);
  vtkGetVector3Macro(OutputSpacing, double);
  ///@}

  ///@{ Grid origin (mm, centre of voxel (0, 0, 0)) and extent (voxel indices); unset (default) =
  /// automatic from the frame corners (see the class description).
  vtkSetVector3Macro(OutputOrigin, double);
  vtkGetVector3Macro(OutputOrigin, double);
  vtkSetVector6Macro(OutputExtent, int);
  vtkGetVector6Macro(OutputExtent, int);
  void SetOutputOriginToDefault();
  void SetOutputExtentToDefault();
  ///@}

  ///@{ Clip rectangle (pixels: first column and row, then width and height); a size of 0 (default)
  /// inserts the whole frame. PLUS's convention, see the class description.
  vtkSetVector2Macro(ClipRectangleOrigin, int);
  vtkGetVector2Macro(ClipRectangleOrigin, int);
  vtkSetVector2Macro(ClipRectangleSize, int);
  vtkGetVector2Macro(ClipRectangleSize, int);
  ///@}

  enum CompoundingModes
  {
    MEAN = 0,
    MAXIMUM = 1,
    LATEST = 2
  };
  ///@{ How the pixels that land in one voxel combine. Default MEAN.
  vtkSetClampMacro(CompoundingMode, int, MEAN, LATEST);
  vtkGetMacro(CompoundingMode, int);
  void SetCompoundingModeToMean() { this->SetCompoundingMode(MEAN); }
  void SetCompoundingModeToMaximum() { this->SetCompoundingMode(MAXIMUM); }
  void SetCompoundingModeToLatest() { this->SetCompoundingMode(LATEST); }
  const char* GetCompoundingModeAsString();
  ///@}

  ///@{ Fill the holes between the inserted pixels (default on).
  vtkSetMacro(FillHoles, bool);
  vtkGetMacro(FillHoles, bool);
  vtkBooleanMacro(FillHoles, bool);
  ///@}

  ///@{ Largest hole-filling cube (voxels per side, odd, 3 .. 15): cubes of side 3, 5, ..., this are
  /// tried in turn (an even value counts as the odd size below it). Default 7: fills the gaps of up to
  /// 5 voxels between neighbouring frames (2.5 mm at 0.5 mm voxels; the spine phantom's frames are 0.8
  /// to 2.8 mm apart).
  vtkSetClampMacro(HoleFillingMaximumKernelSize, int, 3, 15);
  vtkGetMacro(HoleFillingMaximumKernelSize, int);
  ///@}

  ///@{ Gaussian sigma of the 3^3 hole-filling cube (voxels); the cube of radius r uses r times this.
  /// Default 1.
  vtkSetClampMacro(HoleFillingSigma, double, 0.1, 100.0);
  vtkGetMacro(HoleFillingSigma, double);
  ///@}

  ///@{ A hole is filled only when more than this fraction of its cube's voxels were inserted (PLUS's
  /// MinimumKnownVoxelsRatio). Default 0.25: a voxel midway in a gap between two frames sees about
  /// two planes of inserted voxels (2 / 7 of a 7^3 cube) and is filled, a voxel two or more voxels
  /// beyond the last frame sees one (at most 1 / 5) and stays empty, so the volume does not grow
  /// beyond the sweep by more than one voxel.
  vtkSetClampMacro(HoleFillingMinimumKnownRatio, double, 0.0, 1.0);
  vtkGetMacro(HoleFillingMinimumKnownRatio, double);
  ///@}

  ///@{ Largest accepted grid, in voxels (about 8 bytes each while compounding). Default 2^28.
  vtkSetClampMacro(MaximumNumberOfVoxels, vtkIdType, 1, VTK_ID_MAX);
  vtkGetMacro(MaximumNumberOfVoxels, vtkIdType);
  ///@}

  ///@{ Of the last update: frames inserted, pixels inserted into the grid, voxels hit by at least one
  /// pixel, voxels filled as holes, and seconds spent inserting and filling holes.
  vtkGetMacro(NumberOfInsertedFrames, int);
  vtkGetMacro(NumberOfInsertedPixels, vtkIdType);
  vtkGetMacro(NumberOfHitVoxels, vtkIdType);
  vtkGetMacro(NumberOfFilledVoxels, vtkIdType);
  vtkGetMacro(InsertionSeconds, double);
  vtkGetMacro(HoleFillingSeconds, double);
  ///@}

  /// Includes the frame list.
  vtkMTimeType GetMTime() override;

protected:
  vtkUltrasoundVolumeCompounder();
  ~vtkUltrasoundVolumeCompounder() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  vtkIdList* FrameList = nullptr;
  double OutputSpacing[3] = { 0.5, 0.5, 0.5 };
  double OutputOrigin[3];
  int OutputExtent[6];
  int ClipRectangleOrigin[2] = { 0, 0 };
  int ClipRectangleSize[2] = { 0, 0 };
  int CompoundingMode = MEAN;
  bool FillHoles = true;
  int HoleFillingMaximumKernelSize = 7;
  double HoleFillingSigma = 1.0;
  double HoleFillingMinimumKnownRatio = 0.25;
  vtkIdType MaximumNumberOfVoxels = vtkIdType(1) << 28;

  int NumberOfInsertedFrames = 0;
  vtkIdType NumberOfInsertedPixels = 0;
  vtkIdType NumberOfHitVoxels = 0;
  vtkIdType NumberOfFilledVoxels = 0;
  double InsertionSeconds = 0;
  double HoleFillingSeconds = 0;

private:
  vtkUltrasoundVolumeCompounder(const vtkUltrasoundVolumeCompounder&) = delete;
  void operator=(const vtkUltrasoundVolumeCompounder&) = delete;
};

#endif

/**
 * @class   vtkUltrasoundSequenceReader
 * @brief   Reads a tracked ultrasound sweep from a PLUS / IGSIO sequence metafile.
 *
 * Reads `.igs.mha`, `.seq.mha` (header and pixels in one file) and `.mhd` (header) with a detached
 * `.raw` or `.zraw` body, zlib-compressed or not, with MET_UCHAR or MET_FLOAT pixels.
 *
 * Output: the tracked frame sequence of DESIGN section 2, a `vtkImageData` of W x H x N pixels
 * (frame k = slice k, spacing 1 1 1, origin 0 0 0, scalars "Intensity") with field data
 * - `ImageToReference`: N tuples of 16 doubles, row-major 4x4, mapping (column, row, 0, 1) in pixel
 *   indices to millimetres in the reference frame (the pixel spacing is inside the matrix; the
 *   header's ElementSpacing is never applied on top of it);
 * - `Timestamp`: N doubles, seconds;
 * - `FrameValid`: N unsigned chars, 0 where the image or any transform of the chain was INVALID
 *   (its ImageToReference is then the identity and must not be used);
 * - `FrameIndex`: N ints, the frame's number in the file (differs from k when a FrameRange is set).
 *
 * Frames are returned in PLUS's MF orientation: `UltrasoundImageOrientation` UF, MN and UN are
 * flipped on reading, as PLUS does, so that a calibration made for MF applies.
 *
 * How ImageToReference is obtained:
 * - TransformChain empty (default): the per-frame `ImageToReferenceTransform` when the file has it,
 *   otherwise `inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe`.
 * - TransformChain set, e.g. "ImageToReferenceFromTracking" or
 *   "inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe": each factor is looked up, in
 *   order, as the per-frame field Seq_FrameNNNN_<Name>Transform, a matrix given with
 *   SetStaticTransform(), a transform of the PLUS configuration XML (CalibrationFileName; either
 *   direction), or a header-level field <Name>Transform.
 *
 * Errors: a missing file, a malformed or unsupported header, a truncated or corrupt (compressed)
 * body, DimSize that disagrees with the data, a missing, non-numeric or NaN/Inf transform, a
 * singular or sheared ImageToReference (beyond MaximumShearAngle), an unknown status value or a
 * FrameRange outside the file make the pipeline request fail with vtkErrorMacro, an empty output and
 * GetLastErrorText() naming the file, the field and the frame. No pixel or pose is ever guessed.
 */
#ifndef vtkUltrasoundSequenceReader_h
#define vtkUltrasoundSequenceReader_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

#include <memory> // For std::unique_ptr
#include <string> // For std::string

class vtkMatrix4x4;

class BIGUSFILTERS_EXPORT vtkUltrasoundSequenceReader : public vtkImageAlgorithm
{
public:
  static vtkUltrasoundSequenceReader* New();
  vtkTypeMacro(vtkUltrasoundSequenceReader, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// Sequence metafile: .igs.mha, .seq.mha, .mha or .mhd.
  vtkSetStringMacro(FileName);
  vtkGetStringMacro(FileName);

  /**
   * Product of transforms that gives ImageToReference, e.g.
   * "inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe" or just "ImageToReference".
   * Empty (default) chooses automatically (see the class description).
   */
  vtkSetStringMacro(TransformChain);
  vtkGetStringMacro(TransformChain);

  /// The chain actually used by the last successful UpdateInformation().
  const char* GetTransformChainInUse() const;

  /// PLUS device-set configuration XML that holds static transforms such as ImageToProbe.
  vtkSetStringMacro(CalibrationFileName);
  vtkGetStringMacro(CalibrationFileName);

  /**
   * Give a static transform by name (e.g. "ImageToProbe"); the matrix is copied. It is used for
   * factors of the chain that the file has no per-frame field for.
   */
  void SetStaticTransform(const char* name, vtkMatrix4x4* matrix);
  void RemoveAllStaticTransforms();

  /**
   * First and last frame to read (inclusive, numbers in the file). Last = -1 means the last frame
   * of the file. Default 0, -1.
   */
  vtkSetVector2Macro(FrameRange, int);
  vtkGetVector2Macro(FrameRange, int);

  /**
   * Largest accepted deviation of the angle between the image axes of a valid frame from 90 degrees.
   * Default 5 (bigus::DefaultMaximumShearAngle, the renderer's limit): real calibrations carry some
   * shear (the PLUS spine phantom about 2.8 degrees). A sweep read with a larger limit can be
   * compounded or resliced, but the BIGUS trainer and renderer refuse its more sheared frames with an
   * error that names the frame.
   */
  vtkSetClampMacro(MaximumShearAngle, double, 0.0, 90.0);
  vtkGetMacro(MaximumShearAngle, double);

  /// Number of frames in the file (valid after UpdateInformation()).
  vtkGetMacro(NumberOfFramesInFile, int);
  /// UltrasoundImageOrientation of the file ("MF" when absent); output is always MF.
  const char* GetFileOrientation() const;

  /// Message of the last error, naming file, field and frame; empty after a successful update.
  const char* GetLastErrorText() const;

protected:
  vtkUltrasoundSequenceReader();
  ~vtkUltrasoundSequenceReader() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  char* FileName = nullptr;
  char* TransformChain = nullptr;
  char* CalibrationFileName = nullptr;
  int FrameRange[2] = { 0, -1 };
  double MaximumShearAngle;
  int NumberOfFramesInFile = 0;

private:
  vtkUltrasoundSequenceReader(const vtkUltrasoundSequenceReader&) = delete;
  void operator=(const vtkUltrasoundSequenceReader&) = delete;

  int Fail(const std::string& message);

  class vtkInternals;
  std::unique_ptr<vtkInternals> Internals;
};

#endif

/**
 * @class   vtkUltrasoundSequenceWriter
 * @brief   Writes a tracked ultrasound sweep as a PLUS / IGSIO sequence metafile.
 *
 * Input: a tracked frame sequence (DESIGN section 2): `vtkImageData` of W x H x N pixels, unsigned
 * char or float scalars with one component, and field data `ImageToReference` (N x 16 doubles,
 * row-major, pixel index -> mm; required), `Timestamp` (N doubles, s; default: the frame number) and
 * `FrameValid` (N unsigned chars; default 1, 0 is written as transform status INVALID).
 *
 * Output: a `.mha` (`.igs.mha`, `.seq.mha`) with header and pixels in one file, or a `.mhd` header with
 * a detached `.raw` (`.zraw` when compressed) body, in the form PLUS, SlicerIGT / Slicer's Sequences and
 * vtkUltrasoundSequenceReader open: `ElementSpacing = 1 1 1` (the spacing stays inside the matrices),
 * `UltrasoundImageOrientation = MF`, per-frame `Seq_FrameNNNN_<TransformName>Transform`,
 * `...TransformStatus`, `Timestamp` and `ImageStatus`. Numbers are written with the shortest text
 * that reads back to the same double, so a write-read round trip is exact.
 *
 * The file is written under a temporary name and renamed at the end: an existing file is never left
 * half-written. Errors (no input, wrong scalar type, missing or mis-sized ImageToReference, an
 * unwritable folder) are reported with vtkErrorMacro and GetLastErrorText(); nothing is written then.
 */
#ifndef vtkUltrasoundSequenceWriter_h
#define vtkUltrasoundSequenceWriter_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkWriter.h"

#include <string> // For std::string

class vtkImageData;

class BIGUSFILTERS_EXPORT vtkUltrasoundSequenceWriter : public vtkWriter
{
public:
  static vtkUltrasoundSequenceWriter* New();
  vtkTypeMacro(vtkUltrasoundSequenceWriter, vtkWriter);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// Output file: .mha / .igs.mha / .seq.mha (one file) or .mhd (with a .raw or .zraw body).
  vtkSetStringMacro(FileName);
  vtkGetStringMacro(FileName);

  /// zlib-compress the pixel data (default on).
  vtkSetMacro(UseCompression, bool);
  vtkGetMacro(UseCompression, bool);
  vtkBooleanMacro(UseCompression, bool);

  /// zlib level 1 (fastest, default) to 9 (smallest).
  vtkSetClampMacro(CompressionLevel, int, 1, 9);
  vtkGetMacro(CompressionLevel, int);

  /// Name of the per-frame transform written, without the "Transform" suffix. Default "ImageToReference".
  vtkSetStringMacro(TransformName);
  vtkGetStringMacro(TransformName);

  /// Message of the last error; empty after a successful write. A failed write also sets the error code
  /// (vtkErrorCode::UserError), so Write() returns 0.
  const char* GetLastErrorText() const { return this->LastErrorText.c_str(); }

  vtkImageData* GetInput();

protected:
  vtkUltrasoundSequenceWriter();
  ~vtkUltrasoundSequenceWriter() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  void WriteData() override;

  char* FileName = nullptr;
  char* TransformName = nullptr;
  bool UseCompression = true;
  int CompressionLevel = 1;
  std::string LastErrorText;

private:
  vtkUltrasoundSequenceWriter(const vtkUltrasoundSequenceWriter&) = delete;
  void operator=(const vtkUltrasoundSequenceWriter&) = delete;

  void Fail(const std::string& message);
};

#endif

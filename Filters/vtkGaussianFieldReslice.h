/**
 * @class   vtkGaussianFieldReslice
 * @brief   Renders ultrasound slices of a Gaussian scattering field at any plane, like vtkImageReslice.
 *
 * Input: a Gaussian field (vtkPolyData, DESIGN section 2; vtkGaussianFieldTrainer's output).
 * Output: vtkImageData in the coordinates of the reslice axes, with the vocabulary and meaning of
 * vtkImageReslice: output voxel (i, j, k) lies at ResliceAxes * (OutputOrigin + (i, j, k) * OutputSpacing, 1)
 * in the field's reference frame (mm). ResliceAxes columns are the x axis, the y axis, the normal and
 * the origin. OutputDimensionality 2 renders one slice (k = 0), 3 a stack of parallel slices: a volume
 * for vtkImageReslice or a volume mapper. SetInformationInput copies spacing, origin and extent from a
 * reference image.
 *
 * Scalars "Intensity": I = 1 - exp(-gamma max(S, 0)) as float in [0, 1] or unsigned char (x 255,
 * rounded); with OutputScatteringField on, a second point-data array "ScatteringField" holds S (float).
 * ElevationSigma (mm) and gamma default to the field's (field data); Cutoff is the renderer's k.
 *
 * Defaults when nothing is set: identity axes; spacing = the field's PixelSpacing (its training frames'
 * pixel spacing) or 0.5 mm; origin and extent = the field's bounds in the reslice frame (points, padded
 * by three times the largest scale); for OutputDimensionality 2 the slice passes through the axes'
 * origin (z = 0). Using the field's bounds needs the field itself, so the input is brought up to date
 * during RequestInformation when a default is in use.
 *
 * Errors (no field, a malformed field, a singular or sheared ResliceAxes, an empty extent) fail the
 * request with vtkErrorMacro.
 */
#ifndef vtkGaussianFieldReslice_h
#define vtkGaussianFieldReslice_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

class vtkMatrix4x4;

class BIGUSFILTERS_EXPORT vtkGaussianFieldReslice : public vtkImageAlgorithm
{
public:
  static vtkGaussianFieldReslice* New();
  vtkTypeMacro(vtkGaussianFieldReslice, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{ The reslice frame (4x4, columns: x axis, y axis, normal, origin in mm). Held, not copied.
  virtual void SetResliceAxes(vtkMatrix4x4*);
  vtkGetObjectMacro(ResliceAxes, vtkMatrix4x4);
  void SetResliceAxesDirectionCosines(double x0, double x1, double x2, double y0, double y1, double y2, double z0,
    double z1, double z2);
  void SetResliceAxesOrigin(double x, double y, double z);
  ///@}

  ///@{ Output grid in the reslice frame (mm, voxel indices); unset = defaults (see the class description).
  vtkSetVector3Macro(OutputSpacing, double);
  vtkGetVector3Macro(OutputSpacing, double);
  vtkSetVector3Macro(OutputOrigin, double);
  vtkGetVector3Macro(OutputOrigin, double);
  vtkSetVector6Macro(OutputExtent, int);
  vtkGetVector6Macro(OutputExtent, int);
  void SetOutputSpacingToDefault();
  void SetOutputOriginToDefault();
  void SetOutputExtentToDefault();
  vtkSetClampMacro(OutputDimensionality, int, 2, 3);
  vtkGetMacro(OutputDimensionality, int);
  ///@}

  ///@{ Copy spacing, origin and extent from this image's information.
  virtual void SetInformationInput(vtkImageData*);
  vtkGetObjectMacro(InformationInput, vtkImageData);
  ///@}

  ///@{ Elevation beam sigma (mm); negative (default) = the field's ElevationSigma.
  vtkSetMacro(ElevationSigma, double);
  vtkGetMacro(ElevationSigma, double);
  ///@}
  ///@{ Footprint cutoff k (standard deviations). Default 5 (float error in I below 1e-5).
  vtkSetClampMacro(Cutoff, double, 1.0, 20.0);
  vtkGetMacro(Cutoff, double);
  ///@}
  ///@{ Also output the signed scattering field S as point data "ScatteringField".
  vtkSetMacro(OutputScatteringField, bool);
  vtkGetMacro(OutputScatteringField, bool);
  vtkBooleanMacro(OutputScatteringField, bool);
  ///@}
  ///@{ VTK_FLOAT (default, [0, 1]) or VTK_UNSIGNED_CHAR.
  vtkSetMacro(OutputScalarType, int);
  vtkGetMacro(OutputScalarType, int);
  void SetOutputScalarTypeToFloat() { this->SetOutputScalarType(VTK_FLOAT); }
  void SetOutputScalarTypeToUnsignedChar() { this->SetOutputScalarType(VTK_UNSIGNED_CHAR); }
  ///@}
  ///@{ Rendering backend: "cpu" (default) or "auto" (the CUDA renderer when it exists and a GPU is
  /// present; until the CUDA backend lands, "auto" renders on the CPU). Anything else is an error.
  vtkSetStringMacro(Backend);
  vtkGetStringMacro(Backend);
  ///@}

  /// Includes the ResliceAxes matrix and the information input.
  vtkMTimeType GetMTime() override;

protected:
  vtkGaussianFieldReslice();
  ~vtkGaussianFieldReslice() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  vtkMatrix4x4* ResliceAxes = nullptr;
  vtkImageData* InformationInput = nullptr;
  double OutputSpacing[3];
  double OutputOrigin[3];
  int OutputExtent[6];
  int OutputDimensionality = 2;
  double ElevationSigma = -1;
  double Cutoff = 5.0;
  bool OutputScatteringField = false;
  int OutputScalarType = VTK_FLOAT;
  char* Backend = nullptr;

private:
  vtkGaussianFieldReslice(const vtkGaussianFieldReslice&) = delete;
  void operator=(const vtkGaussianFieldReslice&) = delete;
};

#endif

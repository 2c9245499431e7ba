/**
 * @class   vtkPVUltrasoundFrameInterpolator
 * @brief   vtkUltrasoundFrameInterpolator with the trainer's hold-out rule instead of frame lists.
 *
 * Server-manager XML cannot set a vtkIdList. This subclass takes the hold-out rule that
 * vtkGaussianFieldTrainer uses: with N frames in the input sequence (its whole extent along z),
 * frame k is a training frame when k mod HoldOutEvery != HoldOutOffset and a target otherwise, so
 * the baselines predict exactly the frames a field trained with the same rule held out. HoldOutEvery
 * 0 or 1 leaves no target (the request fails with the superclass's error). A held-out training frame
 * whose FrameValid is 0 fails the request, as with the superclass.
 */
#ifndef vtkPVUltrasoundFrameInterpolator_h
#define vtkPVUltrasoundFrameInterpolator_h

#include "bigusParaViewFiltersModule.h" // For export macro
#include "vtkUltrasoundFrameInterpolator.h"

class BIGUSPARAVIEWFILTERS_EXPORT vtkPVUltrasoundFrameInterpolator : public vtkUltrasoundFrameInterpolator
{
public:
  static vtkPVUltrasoundFrameInterpolator* New();
  vtkTypeMacro(vtkPVUltrasoundFrameInterpolator, vtkUltrasoundFrameInterpolator);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{ The hold-out rule (defaults 4 and 2: the benchmark's i mod 4 == 2).
  vtkSetClampMacro(HoldOutEvery, int, 0, VTK_INT_MAX);
  vtkGetMacro(HoldOutEvery, int);
  vtkSetClampMacro(HoldOutOffset, int, 0, VTK_INT_MAX);
  vtkGetMacro(HoldOutOffset, int);
  ///@}

protected:
  vtkPVUltrasoundFrameInterpolator() = default;
  ~vtkPVUltrasoundFrameInterpolator() override = default;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  int HoldOutEvery = 4;
  int HoldOutOffset = 2;

private:
  vtkPVUltrasoundFrameInterpolator(const vtkPVUltrasoundFrameInterpolator&) = delete;
  void operator=(const vtkPVUltrasoundFrameInterpolator&) = delete;
};

#endif

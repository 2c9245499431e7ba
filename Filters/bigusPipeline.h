/**
 * @file    bigusPipeline.h
 * @brief   Pipeline requests shared by the filters of BIGUS::Filters (private, not wrapped).
 */
#ifndef bigusPipeline_h
#define bigusPipeline_h

#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkStreamingDemandDrivenPipeline.h"

namespace bigus
{
/**
 * Asks every connection of one input port for its whole extent (UPDATE_EXTENT = WHOLE_EXTENT), for a
 * filter that needs all of an input (every frame of a sequence, the whole mask) whatever part of its
 * output is requested; by default the executive would pass the output's update extent upstream. A
 * connection without a WHOLE_EXTENT (a vtkPolyData) keeps the request the executive gave it. Call it
 * from RequestUpdateExtent with inputVector[port].
 */
inline void RequestWholeExtent(vtkInformationVector* port)
{
  for (int c = 0; c < port->GetNumberOfInformationObjects(); ++c)
  {
    vtkInformation* inInfo = port->GetInformationObject(c);
    if (inInfo->Has(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()))
    {
      inInfo->Set(vtkStreamingDemandDrivenPipeline::UPDATE_EXTENT(),
        inInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()), 6);
    }
  }
}

/// RequestWholeExtent for each of the input ports 0 to @p numberOfPorts - 1.
inline void RequestWholeExtent(vtkInformationVector** inputVector, int numberOfPorts)
{
  for (int port = 0; port < numberOfPorts; ++port)
  {
    RequestWholeExtent(inputVector[port]);
  }
}
}

#endif

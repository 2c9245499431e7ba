"""BIGUS-VTK: beam-integrated Gaussian scattering for tracked freehand ultrasound.

The VTK classes of the wrapped modules are exposed at package level, e.g.::

    import vtk, bigus
    reader = bigus.vtkUltrasoundSequenceReader()
"""
import vtkmodules.all  # noqa: F401  (VTK's own classes must be registered before ours)

from .bigusRendering import *  # noqa: F401,F403
from .bigusFilters import *  # noqa: F401,F403

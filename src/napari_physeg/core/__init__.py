"""The physics core of napari-physeg: numpy, scipy, scikit-image and OpenCV only.

Scripts, notebooks, batch jobs and the napari widgets all go through
:func:`segment` (and, later, ``match`` and ``simulate``).
"""

from .dynamics import DivergenceError
from .materials import MATERIALS, Material, get_material
from .segmentation import SegmentationResult, segment

__all__ = ["segment", "SegmentationResult", "Material", "MATERIALS", "get_material", "DivergenceError"]

"""The physics core of napari-physeg: numpy, scipy, scikit-image and OpenCV only.

Scripts, notebooks, batch jobs and the napari widgets all go through four
calls: :func:`segment` (a rough contour onto an object's border),
:func:`match` (node correspondences by modal analysis), :func:`simulate`
(the deformation of one contour into another) and :func:`track` (objects
followed through a time-lapse, with membrane maps).
"""

from .dynamics import DivergenceError
from .matching import Matching, MatchingCancelled, MatchingProgress, iter_match, match
from .materials import MATERIALS, Material, get_material
from .segmentation import SegmentationProgress, SegmentationResult, iter_segment, segment
from .simulation import SimulationProgress, SimulationResult, iter_simulate, simulate
from .tracking import LEFT, LOST, TRACKED, TrackingProgress, TrackingResult, iter_track, track

__all__ = [
    "segment",
    "iter_segment",
    "SegmentationResult",
    "SegmentationProgress",
    "match",
    "iter_match",
    "Matching",
    "MatchingProgress",
    "MatchingCancelled",
    "simulate",
    "iter_simulate",
    "SimulationResult",
    "SimulationProgress",
    "Material",
    "MATERIALS",
    "get_material",
    "DivergenceError",
    "track",
    "iter_track",
    "TrackingResult",
    "TrackingProgress",
    "TRACKED",
    "LOST",
    "LEFT",
]

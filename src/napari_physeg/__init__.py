"""napari-physeg: physical deformable contours for napari.

The physics lives in :mod:`napari_physeg.core` (numpy/scipy/scikit-image only);
the napari widgets are thin layers over it.
"""
__version__ = "0.1.0"

"""The image's uneven illumination: a plane, or a dome, under its background.

Microscope images are rarely lit evenly: the excitation or the lamp falls
off across the field, autofluorescence or a bright-field halo adds a slope.
The reading of a drawing compares levels across rings up to twenty times
its size, and the region force compares them across the object: where the
background rises across the field by as much as an object's contrast, its
far side reads brighter than the object. On the real-image benchmark's
confocal nuclei with a background rising corner to corner by their whole
range, circles around nuclei were taken for drawings inside dark holes
(mean IoU 0.94 on the even slices, 0.80 on the sloped ones; ``python
benchmarks/scale.py --slope``).

:func:`background_plane` fits a plane to the image's dominant level by
iteratively reweighted least squares with Tukey's biweight: the objects, far
from that level, get no weight, whatever their polarity.

A dome (a vignette: the field darker toward its corners) is fitted too, by
a quadratic surface, on images of at least DOME_MIN_SIDE px a side. With the
confocal nuclei and the U2OS image vignetted (brightness and background
falling to 40 % at the corners), circles and clicks inside nuclei near the
sides took the brighter middle of the field for the background: mean IoU
0.952 -> 0.874 (held-out confocal slices), 0.929 -> 0.839 (U2OS; every
fourth nucleus of ``benchmarks/real.py``'s cases); with the dome taken out,
0.951 and 0.930. On small crowded images a quadratic surface bends to follow
the objects (on the benchmark's 61 x 57 px slices of a 3D stack it varied by
0.25-0.43 of the image's range, a plane by 0.02-0.18): they get a plane.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["background_plane", "plane_values", "plane_removed"]

#: Pixels the plane is fitted on (a regular sub-grid of the image): three
#: coefficients need few, and the fit's medians cost in proportion.
MAX_SAMPLES = 1024

#: Tukey's biweight constant (95 % efficiency for Gaussian noise), and the
#: most reweightings (on the real-image benchmark's images, even or sloped,
#: the eighth moves the plane by less than 1e-3 of the image's range).
BIWEIGHT_C = 4.685
ITERATIONS = 8

#: The plane is taken out when it rises across the image by at least this
#: fraction of the image's intensity range (1st to 99th percentile). The
#: evenly lit images of the real-image benchmark have planes of 0.01-0.18 of
#: their range, which the robust fit takes from where their objects crowd:
#: taken out of every image, they moved 147 of its 1525 IoUs by more than
#: 0.02, 72 up and 75 down. ``skimage.data.coins()`` (0.32) and ``page()``
#: (0.82) are lit unevenly.
UNEVEN_LIGHT = 0.2

#: Images at least this many pixels on each side may have a dome under their
#: background (a vignette): a quadratic surface, taken out when it departs
#: from the plane by UNEVEN_LIGHT of the range. On small crowded crops a
#: quadratic bends to follow the objects (see the module's docstring).
DOME_MIN_SIDE = 128
#: ... and when its residuals spread at most this many times the plane's.
DOME_SPREAD = 1.1


def background_plane(image: np.ndarray, curved: bool = True) -> np.ndarray | None:
    """The plane ``level + slope_row * row + slope_col * col`` of the
    image's dominant level (its background, in most microscopy), or the
    dome (quadratic surface) when it departs from that plane.

    Parameters
    ----------
    image : (H, W) ndarray
        A real image; pixels that are not finite are left out (and other
        dtypes give None: their error is raised where the image is read).
    curved : bool, optional
        Whether a dome may be fitted (on images of at least DOME_MIN_SIDE
        px a side); False for a plane only.

    Returns
    -------
    ndarray, shape (3,) or (6,), or None
        ``(level, slope_row, slope_col)``, the level at pixel (0, 0) and the
        slopes per pixel, in the image's units; a dome adds the coefficients
        of ``row ** 2``, ``row * col`` and ``col ** 2`` (see
        :func:`plane_values`). None when the image is lit evenly enough (see
        UNEVEN_LIGHT) or has fewer than 3 rows or columns.
    """
    h, w = image.shape
    if min(h, w) < 3 or image.dtype.kind not in "biuf":  # not an image: said where the windows are read
        return None
    step = max(1, int(np.ceil(np.sqrt(h * w / MAX_SAMPLES))))
    # The same image's plane is kept: the widget, batch runs and tracking's
    # objects segment many shapes of one image.
    plane = _plane_of_samples(h, w, step, np.ascontiguousarray(image[::step, ::step], dtype=np.float64).tobytes(),
                              curved and min(h, w) >= DOME_MIN_SIDE)
    return None if plane is None else np.array(plane)


@lru_cache(maxsize=8)
def _plane_of_samples(h: int, w: int, step: int, samples: bytes, curved: bool) -> tuple | None:
    """:func:`background_plane` of an (h, w) image from its pixels every
    ``step`` rows and columns (float64 bytes), as a tuple (or None)."""
    rows, cols = np.mgrid[0:h:step, 0:w:step]
    values = np.frombuffer(samples, dtype=np.float64)
    finite = np.isfinite(values)  # the windows read are validated where they are read
    if np.count_nonzero(finite) < 3:
        return None
    values, rows, cols = values[finite], rows.ravel()[finite], cols.ravel()[finite]
    # Centred, scaled coordinates keep the normal equations well conditioned.
    centre, scale = np.array([(h - 1) / 2, (w - 1) / 2]), float(max(h, w))
    x, y = (rows - centre[0]) / scale, (cols - centre[1]) / scale
    design = np.column_stack([np.ones(values.size), x, y])
    coef = _biweight_fit(design, values)
    lo, hi = _ranks(values, 0.01, 0.99)
    uneven = UNEVEN_LIGHT * (hi - lo)
    if curved:
        quadratic = np.column_stack([design, x * x, x * y, y * y])
        dome = _biweight_fit(quadratic, values)
        # A dome that bends to follow objects (a large one, or a crowd)
        # leaves the background's pixels further from it than the plane
        # does (the spread of the residuals grew 1.4-1.6 times on synthetic
        # ellipses a fifth of the image; it is within 1 % on vignetted
        # confocal slices). Nor can a background vary by more than the
        # image's range: a dome that does follows an object as large as its
        # background (a bright disk over half of the image, where the plane
        # lies between the two levels: the dome rose by 1.6 times the range,
        # and the disk's inside, evenly lit, read as a dark hole; vignetted
        # confocal slices' domes vary by 0.4-0.5 of their range).
        if np.ptp(quadratic @ dome - design @ coef) >= uneven and np.ptp(quadratic @ dome) <= hi - lo and \
                _spread(values - quadratic @ dome) <= DOME_SPREAD * _spread(values - design @ coef):
            return _in_pixels(dome, centre, scale)
    if np.ptp(design @ coef) < uneven:
        return None
    return _in_pixels(coef, centre, scale)


def _in_pixels(coef: np.ndarray, centre: np.ndarray, scale: float) -> tuple:
    """The surface ``coef`` of centred, scaled coordinates ``((row, col) -
    centre) / scale`` (constant, linear, then quadratic terms: xx, xy, yy),
    as the coefficients of :func:`plane_values` in pixels."""
    k = np.zeros(6)
    k[:coef.size] = coef
    (r0, c0), s2 = centre, scale * scale
    a = k[0] - (k[1] * r0 + k[2] * c0) / scale + (k[3] * r0 * r0 + k[4] * r0 * c0 + k[5] * c0 * c0) / s2
    b = k[1] / scale - (2 * k[3] * r0 + k[4] * c0) / s2
    c = k[2] / scale - (k[4] * r0 + 2 * k[5] * c0) / s2
    out = (a, b, c) if coef.size == 3 else (a, b, c, k[3] / s2, k[4] / s2, k[5] / s2)
    return tuple(float(v) for v in out)


def _spread(residual: np.ndarray) -> float:
    """The residuals' robust standard deviation (1.4826 x their median absolute value)."""
    return 1.4826 * _ranks(np.abs(residual), 0.5)[0]


def _biweight_fit(design: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Coefficients of ``values ~ design @ coef`` by iteratively reweighted
    least squares with Tukey's biweight, from the median level."""
    coef = np.zeros(design.shape[1])
    coef[0] = _ranks(values, 0.5)[0]
    for _ in range(ITERATIONS):
        residual = values - design @ coef
        spread = _spread(residual)
        if spread <= 0.0:  # most pixels on the plane already (a flat background)
            break
        u = residual / (BIWEIGHT_C * spread)
        weight = np.clip(1.0 - u * u, 0.0, None) ** 2
        if np.count_nonzero(weight) < design.shape[1]:
            break
        weighted = design * weight[:, None]
        try:
            update = np.linalg.solve(weighted.T @ design, weighted.T @ residual)
        except np.linalg.LinAlgError:  # the weighted pixels lie on a line
            break
        coef += update
        if np.abs(update).max() < 1e-4 * spread:
            break
    return coef


def _ranks(values: np.ndarray, *fractions: float) -> list[float]:
    """The values at these fractions of the sorted ``values`` (nearest rank;
    np.partition: np.median and np.percentile cost several times more on
    these few samples)."""
    kth = [min(int(f * values.size), values.size - 1) for f in fractions]
    part = np.partition(values, kth)
    return [float(part[k]) for k in kth]


def plane_removed(image: np.ndarray, plane: np.ndarray | None, window: tuple[slice, slice]) -> np.ndarray:
    """``image`` (float, the image on ``window``) with the plane taken out
    (itself when there is no plane)."""
    return image if plane is None else image - plane_values(plane, window)


def plane_values(plane: np.ndarray, window: tuple[slice, slice]) -> np.ndarray:
    """The plane's (or dome's) values on ``window`` (a pair of slices with explicit bounds)."""
    rows = np.arange(window[0].start, window[0].stop, dtype=np.float64)[:, None]
    cols = np.arange(window[1].start, window[1].stop, dtype=np.float64)[None, :]
    values = plane[0] + plane[1] * rows + plane[2] * cols
    if len(plane) == 6:
        values = values + plane[3] * rows * rows + plane[4] * rows * cols + plane[5] * cols * cols
    return values

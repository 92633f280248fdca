"""What tells an object from its background: its level, or its texture.

In fluorescence and stained images an object stands out by its level: it
is brighter (or darker) than the ground about it, and the region force reads
that level (:mod:`.region`). Flat cells in phase contrast or bright field
do not: their bodies lie at about the ground's level, ringed by bright
halos and dotted with dark granules, and what sets them apart is that
their pixels vary where the ground's do not. Read by level, a circle about
such a cell shrank onto a granule or spread along the halos (mean IoU 0.27
on 71 migrating T98G cells, 0.33 on 93 drawings about adherent epithelial
cells).

There, the object is read on its *texture*: the local standard deviation of
the image (:func:`texture_map`), on which the cell is a bright body on a
dark ground, and every force and reading of the segmentation applies as on
a fluorescent one. Which of the two tells the object is read from the
drawing (:func:`told_by_texture`): the pixels in its middle against those
in a ring about it, by level and by texture, each difference in units of
the pixels' own spread.
"""

from __future__ import annotations

import cv2
import numpy as np

from .contour import bounding_window, signed_area
from .region import _TWO_SIDED_SHARE, _fill, _scaled, _scatter

__all__ = ["CONTRASTS", "texture_map", "told_by_texture"]

#: What may tell the object from its background (segment's ``contrast``).
CONTRASTS = ("auto", "intensity", "texture")

#: The texture is the standard deviation within a Gaussian window of this
#: many px: the size of the granules and halos of cells in phase contrast at
#: the usual magnifications (a few px), small enough for the border to stay
#: within a pixel or two of where the cell's variation ends.
TEXTURE_SIGMA = 2.0

#: The drawing's middle (its scale about its centroid) and the ring about it
#: (between the drawing and this scale of it) whose pixels are compared.
_MIDDLE_SCALE = 0.5
_RING_SCALE = 1.5

#: The level tells the object where its middle and its ring differ by at
#: least LEVEL_SEEN of their pixels' spreads; below, the texture does where
#: it tells them apart by at least TEXTURE_SEEN spreads, and TEXTURE_GAIN
#: times better. (Without TEXTURE_SEEN, drawings inside coins and nuclei,
#: whose middle and ring differ in nothing, read the faintest difference of
#: texture as the object: IoU 0.98 -> 0.91 on coins.)
LEVEL_SEEN = 1.2
TEXTURE_SEEN = 1.0
TEXTURE_GAIN = 2.0

#: A textured object holds pixels beyond its ground's levels *both ways*
#: (bright halos and dark granules): more than _TWO_SIDED_SHARE of its
#: middle's pixels each way, beyond GROUND_SPREADS of the ring's spreads
#: from the ring's level (noise alone puts 0.13 % each way). A fluorescent
#: object lies one way, however many edges cross its drawing: a box twice
#: the size of a nucleus in a crowd held its edges and its neighbours' in
#: its middle and ring, and read as textured, its contour took the crowd
#: (IoU 0.78 -> 0.40; 18 such drawings of 4,800 on fluorescent and stained
#: images read so, none with this rule). And the grain swings both ways
#: alike: its brightest and darkest pixels (the middle's 99th and 1st
#: percentiles) lie within GRAIN_SYMMETRY times as far from the ground's
#: level as each other (0.6-2.6 about flat cells in phase contrast, up to 5
#: about cells in DIC, whose relief is lit brighter on one side than it is
#: shaded on the other). A cell with a level of its own in a dark halo
#: swings far one way (a thin bright cell among haloed ones, boxed: 26; read
#: by texture, IoU 0.93 -> 0.32). (At 4, circles and lassos about 9 CHO
#: cells in DIC were read by level and outlined the lit half: IoU 0.33-0.47;
#: at 8, the middle of 2.6 and 26 on a log scale, 0.82-0.92, and no drawing
#: of 8,800 on other images moved; an outside tester, session 73.)
GROUND_SPREADS = 3.0
GRAIN_SYMMETRY = 8.0

#: A texture is read over many of its windows: only a drawing at least this
#: large (the radius of a disk of its area, px) is read by it, its middle
#: then 4 windows in radius. Over smaller ones the texture is that of an edge
#: the drawing crosses (a small circle over a nucleus' edge, its middle on
#: the edge's band, took the texture of the edge for the object: IoU 0.76 ->
#: 0.56 over 113 such circles on a crowd of nuclei), or of a few granules.
#: Flat cells in phase contrast are drawn about at 20-60 px.
TEXTURE_DRAWING_RADIUS = 8 * TEXTURE_SIGMA


def texture_map(image: np.ndarray, sigma: float = TEXTURE_SIGMA) -> np.ndarray:
    """The local standard deviation of ``image`` (float64) within a Gaussian
    window of ``sigma`` px: high where the image varies (a cell's granules
    and halos in phase contrast), low on even ground.

    NaN pixels (no data) stay NaN and do not enter their neighbours' values.
    """
    image = np.asarray(image, dtype=np.float64)
    missing = np.isnan(image)
    known = (~missing).astype(np.float64)
    # (Centred first, for the precision of the squares; missing pixels weigh nothing.)
    values = np.where(missing, 0.0, image - (image[~missing].mean() if (~missing).any() else 0.0))

    def smoothed(a):
        return cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)

    weight = smoothed(known) if missing.any() else 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = smoothed(values) / weight
        spread = np.sqrt(np.maximum(smoothed(values * values) / weight - mean * mean, 0.0))
    spread[missing] = np.nan
    return spread


def told_by_texture(image: np.ndarray, drawing: np.ndarray) -> bool:
    """Whether the object ``drawing`` (``(N, 2)`` row, col) marks on
    ``image`` is told from its background by its texture rather than by its
    level (see LEVEL_SEEN). False for a drawing too small to
    read its texture over (see TEXTURE_DRAWING_RADIUS; a click)."""
    drawing = np.asarray(drawing, dtype=np.float64)
    if abs(signed_area(drawing)) < np.pi * TEXTURE_DRAWING_RADIUS**2:
        return False
    ring_outline = _scaled(drawing, _RING_SCALE)
    window = bounding_window(ring_outline, image.shape, 3.0 * TEXTURE_SIGMA)
    values = np.asarray(image[window], dtype=np.float64)
    corner = np.array([window[0].start, window[1].start])
    known = ~np.isnan(values)
    middle = _fill(_scaled(drawing, _MIDDLE_SCALE), values.shape, corner) & known
    ring = _fill(ring_outline, values.shape, corner) & ~_fill(drawing, values.shape, corner) & known
    if not (middle.any() and ring.any()):  # (the image's side cuts all of one off)
        return False
    filled = np.where(known, values, np.nanmedian(values))
    level = cv2.GaussianBlur(filled, (0, 0), 1.0, borderType=cv2.BORDER_REFLECT)
    if not _grainy(level[middle], level[ring]):
        return False
    by_level, by_texture = _separation(level, middle, ring), _separation(texture_map(filled), middle, ring)
    return bool(abs(by_level) < LEVEL_SEEN and by_texture > max(TEXTURE_SEEN, TEXTURE_GAIN * abs(by_level)))


def _grainy(middle: np.ndarray, ground: np.ndarray) -> bool:
    """Whether the levels ``middle`` swing about those of ``ground`` as a
    grain does: more than _TWO_SIDED_SHARE of them beyond GROUND_SPREADS
    spreads of the ground's from its median, each way, and about as far
    each way (see GRAIN_SYMMETRY)."""
    level, spread = float(np.median(ground)), GROUND_SPREADS * _scatter(ground)
    if min(np.mean(middle > level + spread), np.mean(middle < level - spread)) <= _TWO_SIDED_SHARE:
        return False
    brighter, darker = np.percentile(middle, 99) - level, level - np.percentile(middle, 1)
    return bool(max(brighter, darker) <= GRAIN_SYMMETRY * min(brighter, darker))


def _separation(values: np.ndarray, middle: np.ndarray, ring: np.ndarray) -> float:
    """How far the median of ``values`` in ``middle`` lies above that in
    ``ring``, in units of their pixels' robust spread (the root mean square
    of the two median absolute deviations)."""
    a, b = values[middle], values[ring]
    spread = np.sqrt(0.5 * (_scatter(a) ** 2 + _scatter(b) ** 2))
    difference = float(np.median(a) - np.median(b))
    return difference / spread if spread > 0 else (0.0 if difference == 0 else np.inf * np.sign(difference))


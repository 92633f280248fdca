"""Synthetic test images with a known answer (like :mod:`skimage.data`).

Every generator returns a :class:`SyntheticObject`: an image, the true object
mask, its true outline and two initial contours (one close to the object, one
far from it) so that segmentation, matching and deformation code can be tested
against ground truth.

Conventions
-----------
* Coordinates are napari's / scikit-image's ``(row, col)`` float64; pixel
  ``(i, j)`` has its centre at ``(i, j)``.
* Contours are ``(N, 2)`` arrays, closed implicitly (the first node is not
  repeated), sampled at about one node per pixel, and positively oriented:
  the shoelace area with rows as the first axis,
  ``0.5 * sum(r[i] * c[i+1] - r[i+1] * c[i])``, is positive.  On screen (rows
  down) this is the counter-clockwise direction.
* Images are float64: background 0.3, object ``0.3 + 0.4 * contrast``
  (swapped for a dark object), anti-aliased by 5x5 super-sampling, plus
  Gaussian noise whose standard deviation is ``noise`` times the object /
  background step ``0.4 * contrast``.  Values are not clipped.
* Everything is deterministic for a given ``seed``.

Only numpy, scipy and scikit-image are used, so this module can be imported
without napari or Qt.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import MappingProxyType

import numpy as np
from scipy import ndimage as ndi
from scipy.interpolate import CubicSpline

from .core.contour import polygon_mask, positively_oriented, resample

__all__ = [
    "SyntheticObject",
    "ellipse",
    "blob",
    "hand",
    "hand_outline",
    "hand_pair",
    "HAND_POSES",
    "HAND_FINGERS",
    "smooth_warp",
    "sample_segmentation",
    "SyntheticMovie",
    "deforming_cell",
]

_BACKGROUND = 0.3
_STEP = 0.4
_SUPERSAMPLE = 5  # odd, so that no pixel has a coverage of exactly 0.5
#: Distance (px) of ``init_near`` outside the object.
_NEAR_DISTANCE = 6.0
#: Smallest radius (px) of the concave bends of ``init_near``.
_NEAR_ROUNDING = 4.0
#: Margin of ``init_far`` around the object, relative to the object's size.
_FAR_MARGIN = 0.2


@dataclass(frozen=True, eq=False, repr=False)
class SyntheticObject:
    """A synthetic image of one object with its ground truth.

    Attributes
    ----------
    image : ndarray of float64, shape (H, W)
        The (anti-aliased, possibly noisy) image.
    mask : ndarray of bool, shape (H, W)
        The true object: one 4-connected component without holes, not touching
        the image border.
    outline : ndarray of float64, shape (N, 2)
        The true border as a closed ``(row, col)`` contour (first node not
        repeated), about 1 px between nodes, positively oriented.
    init_near : ndarray of float64, shape (M, 2)
        A smooth initial contour about 6 px outside the object; it encloses the
        object without touching it.
    init_far : ndarray of float64, shape (K, 2)
        An ellipse enclosing the object with a margin of up to 20 % of the
        object's size (less where the image is too small), inside the image.
    name : str
        A short description, e.g. ``"hand-open"``.
    """

    image: np.ndarray
    mask: np.ndarray
    outline: np.ndarray
    init_near: np.ndarray
    init_far: np.ndarray
    name: str

    def __repr__(self) -> str:
        return (f"SyntheticObject(name={self.name!r}, image={self.image.shape}, "
                f"mask area={int(self.mask.sum())}, outline={len(self.outline)} nodes, "
                f"init_near={len(self.init_near)} nodes, init_far={len(self.init_far)} nodes)")


# --------------------------------------------------------------------------
# Contour helpers
# --------------------------------------------------------------------------


def _open_closed(contour: np.ndarray) -> np.ndarray:
    """Drop the repeated closing node of a ``find_contours`` contour and
    consecutive duplicate nodes."""
    contour = np.asarray(contour, dtype=np.float64)
    keep = np.any(contour != np.roll(contour, 1, axis=0), axis=1)
    return contour[keep]


def _resample_closed(contour: np.ndarray, n_nodes: int | None = None, *, spacing: float = 1.0,
                     start_at: int = 0) -> np.ndarray:
    """:func:`~napari_physeg.core.contour.resample` starting at node ``start_at``."""
    contour = np.roll(np.asarray(contour, dtype=np.float64), -start_at, axis=0)
    return resample(contour, n_nodes, spacing=None if n_nodes is not None else spacing)


_polygon_mask = polygon_mask


def _polygon_coverage(contour: np.ndarray, shape, factor: int = _SUPERSAMPLE) -> np.ndarray:
    """Fraction of each pixel inside the polygon, by ``factor x factor``
    super-sampling within the polygon's bounding box."""
    h, w = int(shape[0]), int(shape[1])
    lo = np.clip(np.floor(contour.min(axis=0)).astype(int) - 1, 0, [h, w])
    hi = np.clip(np.ceil(contour.max(axis=0)).astype(int) + 2, 0, [h, w])
    window = (int(hi[0] - lo[0]), int(hi[1] - lo[1]))
    coverage = np.zeros((h, w), dtype=np.float64)
    if min(window) <= 0:
        return coverage
    fine = _polygon_mask(_to_fine(contour - lo, factor), (window[0] * factor, window[1] * factor))
    coverage[lo[0]:hi[0], lo[1]:hi[1]] = _downsample(fine.astype(np.float64), factor)
    return coverage


def _subpixel_grid(shape, factor: int = _SUPERSAMPLE):
    """Centres of the ``factor x factor`` sub-pixels, in pixel coordinates."""
    h, w = shape
    rr = (np.arange(h * factor) + 0.5) / factor - 0.5
    cc = (np.arange(w * factor) + 0.5) / factor - 0.5
    return rr, cc


def _downsample(fine: np.ndarray, factor: int = _SUPERSAMPLE) -> np.ndarray:
    h, w = fine.shape[0] // factor, fine.shape[1] // factor
    return fine.reshape(h, factor, w, factor).mean(axis=(1, 3))


def _to_fine(contour, factor: int = _SUPERSAMPLE) -> np.ndarray:
    """Pixel coordinates -> sub-pixel index coordinates."""
    return (np.asarray(contour) + 0.5) * factor - 0.5


def _largest_component(mask: np.ndarray) -> np.ndarray:
    lab, n = ndi.label(mask)
    if n <= 1:
        return mask.astype(bool)
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    return lab == int(np.argmax(sizes))


def _contour_of(field: np.ndarray, level: float = 0.5) -> np.ndarray:
    """Longest closed iso-contour of ``field``, positively oriented, first node
    not repeated."""
    from skimage.measure import find_contours

    contours = find_contours(field, level)
    if not contours:
        raise RuntimeError("no contour found")
    longest = max(contours, key=len)
    return positively_oriented(_open_closed(longest))


def _coverage_outline(coverage: np.ndarray) -> np.ndarray:
    """The 0.5 iso-contour of a pixel coverage map, resampled at ~1 px."""
    return _resample_closed(_contour_of(coverage, 0.5), spacing=1.0)


def _init_near(mask: np.ndarray, distance: float = _NEAR_DISTANCE,
               rounding: float = _NEAR_ROUNDING) -> np.ndarray:
    """Smooth contour about ``distance`` px outside ``mask``.

    The border of the object dilated by ``distance`` and then morphologically
    closed by a disk of radius ``rounding``: it stays at least ``distance``
    from the object, bridges concavities narrower than
    ``2 * (distance + rounding)``, follows wider ones, and bends with a radius
    of at least ``rounding`` in concave places and ``distance`` in convex ones.
    """
    reach = distance + rounding
    dilated = ndi.distance_transform_edt(~mask) <= reach  # dilation by distance + rounding
    field = ndi.distance_transform_edt(dilated)  # eroding it by rounding closes it
    field = ndi.gaussian_filter(field, 1.0)
    contour = _resample_closed(_contour_of(field, rounding), spacing=1.0)
    smooth = ndi.gaussian_filter1d(contour, 2.0, axis=0, mode="wrap")
    return positively_oriented(_resample_closed(smooth, spacing=1.0))


def _enclosing_ellipse(outline: np.ndarray, shape, margin: float = _FAR_MARGIN,
                       border: float = 2.0) -> np.ndarray:
    """Axis-aligned ellipse around ``outline``.

    Centred on the outline's bounding box, with the box's aspect ratio, just
    large enough to enclose the outline, then grown by ``margin`` times the
    object's size (the larger side of its bounding box) along both axes, but
    shrunk where needed to stay ``border`` px inside the image.
    """
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = np.maximum(0.5 * (hi - lo), 1.0)
    rho = np.hypot(*((outline - centre) / half).T).max()
    need = half * rho + 1.5  # encloses every node (and the polygon) with 1.5 px to spare
    want = half * rho + margin * 2.0 * half.max()
    room = np.minimum(centre, np.asarray(shape, dtype=float) - 1.0 - centre) - border
    axes = np.maximum(np.minimum(want, room), need)
    if np.any(axes > room + 1e-9):
        raise ValueError("the object is too large for the image: no ellipse enclosing it fits inside "
                         "(use a larger shape or a smaller object)")
    n = max(int(np.ceil(np.pi * (3 * (axes[0] + axes[1]) - np.sqrt((3 * axes[0] + axes[1])
                                                                    * (axes[0] + 3 * axes[1]))))), 16)
    t = np.linspace(0.0, 2 * np.pi, 8 * n, endpoint=False)
    dense = centre + np.column_stack([axes[0] * np.cos(t), axes[1] * np.sin(t)])
    return positively_oriented(_resample_closed(dense, n))


def _render(coverage: np.ndarray, *, bright: bool, contrast: float, noise: float,
            seed) -> np.ndarray:
    step = _STEP * float(contrast)
    if bright:
        image = _BACKGROUND + step * coverage
    else:
        image = (_BACKGROUND + step) - step * coverage
    if noise:
        rng = np.random.default_rng(seed)
        image = image + rng.normal(0.0, float(noise) * abs(step), size=image.shape)
    return np.ascontiguousarray(image, dtype=np.float64)


def _clean_mask(coverage: np.ndarray) -> np.ndarray:
    mask = _largest_component(coverage > 0.5)
    return ndi.binary_fill_holes(mask)


def _check_shape(shape) -> tuple[int, int]:
    shape = tuple(int(s) for s in shape)
    if len(shape) != 2 or min(shape) < 32:
        raise ValueError(f"shape must be a 2D shape of at least 32 x 32 pixels, got {shape}")
    return shape


def _check_noise(noise: float) -> float:
    noise = float(noise)
    if not np.isfinite(noise) or noise < 0:
        raise ValueError(f"noise must be a finite non-negative number, got {noise}")
    return noise


def _assemble(coverage, outline, name, *, bright, contrast, noise, seed) -> SyntheticObject:
    mask = _clean_mask(coverage)
    image = _render(coverage, bright=bright, contrast=contrast, noise=noise, seed=seed)
    return SyntheticObject(
        image=image,
        mask=mask,
        outline=outline,
        init_near=_init_near(mask),
        init_far=_enclosing_ellipse(outline, coverage.shape),
        name=name,
    )


# --------------------------------------------------------------------------
# Ellipse
# --------------------------------------------------------------------------


def ellipse(shape=(256, 256), *, center=None, axes=None, angle: float = 0.0, bright: bool = True,
            noise: float = 0.0, contrast: float = 1.0, seed=0) -> SyntheticObject:
    """An elliptical object.

    Parameters
    ----------
    shape : tuple of int, optional
        Image shape ``(rows, cols)``.
    center : tuple of float, optional
        Centre ``(row, col)``; the image centre by default.
    axes : tuple of float, optional
        Semi-axes ``(a, b)`` in pixels; ``a`` lies along the rows when
        ``angle`` is 0.  Default ``(0.3 * rows, 0.2 * cols)``.
    angle : float, optional
        Rotation in radians, with the same convention as
        ``skimage.draw.ellipse(..., rotation=angle)``: the ``a`` axis points
        along ``(cos(angle), sin(angle))`` in ``(row, col)``.
    bright : bool, optional
        Bright object on a dark background (default) or the reverse.
    noise : float, optional
        Standard deviation of additive Gaussian noise relative to the
        object/background step.
    contrast : float, optional
        Object/background step in units of 0.4.
    seed : int or numpy.random.Generator seed, optional
        Seed of the noise.

    Returns
    -------
    SyntheticObject
        ``outline`` is the analytic ellipse sampled at ~1 px.
    """
    shape = _check_shape(shape)
    noise = _check_noise(noise)
    h, w = shape
    if center is None:
        center = ((h - 1) / 2.0, (w - 1) / 2.0)
    if axes is None:
        axes = (0.3 * h, 0.2 * w)
    r0, c0 = (float(v) for v in center)
    a, b = (float(v) for v in axes)
    if a <= 0 or b <= 0:
        raise ValueError(f"axes must be positive, got {axes}")
    ca, sa = np.cos(angle), np.sin(angle)

    # Super-sample within the ellipse's bounding box only.
    half_r = np.hypot(a * ca, b * sa)
    half_c = np.hypot(a * sa, b * ca)
    i0, i1 = int(np.clip(np.floor(r0 - half_r) - 1, 0, h)), int(np.clip(np.ceil(r0 + half_r) + 2, 0, h))
    j0, j1 = int(np.clip(np.floor(c0 - half_c) - 1, 0, w)), int(np.clip(np.ceil(c0 + half_c) + 2, 0, w))
    rr, cc = _subpixel_grid((i1 - i0, j1 - j0))
    dr = rr[:, None] + i0 - r0
    dc = cc[None, :] + j0 - c0
    inside = ((dr * ca + dc * sa) / a) ** 2 + ((dr * sa - dc * ca) / b) ** 2 <= 1.0
    coverage = np.zeros(shape, dtype=np.float64)
    coverage[i0:i1, j0:j1] = _downsample(inside.astype(np.float64))

    perim = np.pi * (3 * (a + b) - np.sqrt((3 * a + b) * (a + 3 * b)))
    t = np.linspace(0.0, 2 * np.pi, 16 * max(int(perim), 16), endpoint=False)
    dense = np.column_stack([
        r0 + a * np.cos(t) * ca + b * np.sin(t) * sa,
        c0 + a * np.cos(t) * sa - b * np.sin(t) * ca,
    ])
    outline = positively_oriented(_resample_closed(dense, max(int(round(perim)), 8)))
    if not _clean_mask(coverage).any():
        raise ValueError("the ellipse covers no pixel centre")
    name = f"ellipse-{'bright' if bright else 'dark'}"
    return _assemble(coverage, outline, name, bright=bright, contrast=contrast, noise=noise, seed=seed)


# --------------------------------------------------------------------------
# Blob
# --------------------------------------------------------------------------


_BLOB_MAX_SOLIDITY = 0.95
_BLOB_BASE = 256  # blobs are drawn at most this size, then interpolated


def _blob_candidate(shape, blob_seed):
    """One attempt at a blob for ``blob_seed``: its pixel coverage, or None.

    The blob is drawn on a grid of at most 256 pixels a side and its smoothed
    field interpolated up to ``shape``, so that it scales with the image.
    Cheap checks run on the coarse grid first; only a promising component is
    super-sampled (within its bounding box).
    """
    from skimage.data import binary_blobs
    from skimage.morphology import convex_hull_image

    h, w = shape
    length = min(max(h, w), _BLOB_BASE)
    zoom = max(h, w) / length
    hb, wb = max(int(h / zoom), 1), max(int(w / zoom), 1)
    blobs = binary_blobs(length=length, blob_size_fraction=0.25, volume_fraction=0.35,
                         rng=blob_seed)[:hb, :wb]
    lab, n = ndi.label(blobs)
    if n == 0:
        return None
    touching = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    sizes = np.bincount(lab.ravel(), minlength=n + 1).astype(float)
    sizes[0] = 0
    sizes[touching] = 0
    best = int(np.argmax(sizes))
    if sizes[best] < 0.04 * hb * wb:
        return None
    comp = ndi.binary_fill_holes(lab == best)
    rows, cols = np.nonzero(comp)
    r_lo, r_hi, c_lo, c_hi = rows.min(), rows.max(), cols.min(), cols.max()
    bh, bw = r_hi - r_lo + 1, c_hi - c_lo + 1
    if bh > 0.7 * hb or bw > 0.7 * wb:
        return None
    # Smooth slightly: the object is the 0.5 level of the smoothed mask.
    pad = 8
    patch = np.zeros((bh + 2 * pad, bw + 2 * pad))
    patch[pad:pad + bh, pad:pad + bw] = comp[r_lo:r_hi + 1, c_lo:c_hi + 1]
    field = ndi.gaussian_filter(patch, 0.01 * length + 1.0)
    coarse = field > 0.5
    if ndi.label(coarse)[1] != 1 or ndi.label(~coarse)[1] != 1:
        return None
    if coarse.sum() > _BLOB_MAX_SOLIDITY * convex_hull_image(coarse).sum():
        return None  # nearly convex: not an interesting test object
    # Interpolate the field up to the image resolution times the super-sampling
    # factor, and place it at the centre of the image.
    ph, pw = int(round(patch.shape[0] * zoom)), int(round(patch.shape[1] * zoom))
    if ph + 2 > h or pw + 2 > w:
        return None
    fine = ndi.zoom(field, (ph * _SUPERSAMPLE / patch.shape[0], pw * _SUPERSAMPLE / patch.shape[1]),
                    order=1, grid_mode=True, mode="nearest") > 0.5
    coverage = np.zeros(shape, dtype=np.float64)
    top, left = (h - ph) // 2, (w - pw) // 2
    coverage[top:top + ph, left:left + pw] = _downsample(fine.astype(np.float64))
    return coverage


def _blob_is_valid(coverage, outline) -> bool:
    mask = _clean_mask(coverage)
    if ndi.label(mask)[1] != 1 or ndi.label(~mask)[1] != 1:
        return False
    if mask[:8].any() or mask[-8:].any() or mask[:, :8].any() or mask[:, -8:].any():
        return False
    poly = _polygon_mask(outline, mask.shape)
    iou = (poly & mask).sum() / max((poly | mask).sum(), 1)
    if iou < 0.985:
        return False
    try:
        _enclosing_ellipse(outline, mask.shape)
    except ValueError:
        return False
    return True


def blob(shape=(256, 256), *, bright: bool = True, noise: float = 0.0, contrast: float = 1.0,
         seed=0) -> SyntheticObject:
    """A single smooth, irregular blob.

    Built from :func:`skimage.data.binary_blobs` (``blob_size_fraction=0.25``,
    ``volume_fraction=0.35``; larger blob sizes give near-circular blobs): the
    largest connected component not touching the border is kept, its holes
    filled, it is moved to the image centre and smoothed slightly (Gaussian of
    the mask, level 0.5).  When a seed gives no suitable component (smaller
    than 4 % of the image, wider than 70 % of it, nearly convex with solidity
    above 0.95, or with necks too thin to be one clean component), further
    seeds derived deterministically from ``seed`` are tried.

    Parameters
    ----------
    shape : tuple of int, optional
        Image shape ``(rows, cols)``.
    bright : bool, optional
        Bright object on a dark background (default) or the reverse.
    noise : float, optional
        Standard deviation of additive Gaussian noise relative to the
        object/background step.
    contrast : float, optional
        Object/background step in units of 0.4.
    seed : int, optional
        Seed of the blob shape and of the noise.

    Returns
    -------
    SyntheticObject
        ``outline`` is the 0.5 iso-contour (``skimage.measure.find_contours``)
        of the pixel coverage, resampled at ~1 px.
    """
    shape = _check_shape(shape)
    noise = _check_noise(noise)
    seed = int(seed)
    for attempt in range(200):
        blob_seed = seed if attempt == 0 else int(np.random.SeedSequence([seed, attempt]).generate_state(1)[0])
        coverage = _blob_candidate(shape, blob_seed)
        if coverage is None:
            continue
        outline = _coverage_outline(coverage)
        if _blob_is_valid(coverage, outline):
            name = f"blob-{seed}-{'bright' if bright else 'dark'}"
            return _assemble(coverage, outline, name, bright=bright, contrast=contrast, noise=noise,
                             seed=seed)
    raise RuntimeError(f"no suitable blob found for seed {seed} and shape {shape}")  # pragma: no cover


# --------------------------------------------------------------------------
# Hand
# --------------------------------------------------------------------------
#
# The hand is described in "hand units" (palm width ~ 1) in an (x, y) frame with
# y pointing up, the origin in the middle of the knuckle line.  Its outline is a
# chain of pieces traversed counter-clockwise (which is also the positive
# orientation once mapped to (row, col) = (-y, x)):
#
#   palm_right (bottom centre -> pinky outer base corner),
#   for each finger from the pinky to the index: outer side (up), tip (half
#   circle), inner side (down), then a web to the next finger,
#   the thumb (inner side, tip, outer side), palm_left (-> bottom centre).
#   The thumb's inner side starts _THUMB_WEB_OFFSET up from its base, so the
#   web between thumb and index stays a rounded U whatever the thumb's angle.
#
# Each finger is a capsule of half-width w rotated about its base centre b by
# an angle phi (from +y, positive toward the pinky): its sides are straight
# segments of fixed length and its tip a half circle, whatever the pose.  The
# webs and palm sides are cubic curves whose end tangents follow the fingers.
#
# Canonical parameter: each piece owns a fixed share of [0, 1) (its arc length
# in the "open" pose divided by the open perimeter) and within a piece the
# parameter grows linearly with arc length.  The same value therefore denotes
# the same anatomical point (finger k, side, relative position t) in every pose.

#: Finger names, in the order of the finger labels 0..4.
HAND_FINGERS = ("thumb", "index", "middle", "ring", "pinky")

# base centre (x, y), length (base centre to tip centre), half-width
_FINGER_BASE = np.array([[-0.50, -0.50], [-0.39, -0.01], [-0.13, 0.02], [0.13, 0.00], [0.38, -0.07]])
_FINGER_LENGTH = np.array([0.62, 0.80, 0.90, 0.84, 0.66])
_FINGER_WIDTH = np.array([0.10, 0.080, 0.085, 0.080, 0.070])

#: Finger angles in degrees (thumb, index, middle, ring, pinky) for each pose,
#: measured from the hand's axis (toward the fingertips), positive toward the
#: pinky.  Read-only.
HAND_POSES = MappingProxyType({
    "open": (-45.0, -10.0, -2.0, 6.0, 14.0),
    "closed": (-30.0, 4.0, 0.0, -3.8, -8.8),
    "spread": (-62.0, -20.0, -4.0, 12.0, 28.0),
})

# Palm control points (x, y) between the bottom centre and the fingers.
_PALM_RIGHT = np.array([[0.0, -1.0], [0.30, -0.985], [0.47, -0.86], [0.535, -0.58]])
_PALM_LEFT = np.array([[-0.47, -0.80], [-0.32, -0.965], [0.0, -1.0]])
_THUMB_WEB_OFFSET = 0.25  # the thumb's inner side is this much shorter than its outer side
_WEB_TANGENT = 0.35  # web control-arm length relative to the web's chord
_PIECE_SAMPLES = 400


def _fingers(pose: str):
    if pose not in HAND_POSES:
        raise ValueError(f"unknown pose {pose!r}; choose one of {sorted(HAND_POSES)}")
    phi = np.deg2rad(np.asarray(HAND_POSES[pose], dtype=np.float64))
    u = np.column_stack([np.sin(phi), np.cos(phi)])  # finger direction
    n = np.column_stack([np.cos(phi), -np.sin(phi)])  # right-hand normal
    base = _FINGER_BASE
    tip = base + _FINGER_LENGTH[:, None] * u
    return base, tip, u, n, _FINGER_WIDTH


def _finger_gaps(pose: str) -> np.ndarray:
    """Narrowest gap between adjacent fingers (thumb-index, index-middle,
    middle-ring, ring-pinky), in hand units.

    The distance between the finger capsules (axis segments from the base
    centre to the tip centre, minus the half-widths); for the thumb only the
    part above its inner corner, which is free of the palm, counts.
    """
    base, tip, u, _, w = _fingers(pose)
    start = base.copy()
    start[0] = base[0] + _THUMB_WEB_OFFSET * u[0]
    return np.array([_segment_distance(start[k], tip[k], start[k + 1], tip[k + 1]) - w[k] - w[k + 1]
                     for k in range(4)])


def _segment_distance(p0, p1, q0, q1) -> float:
    """Distance between the segments p0-p1 and q0-q1 (assumed not to cross)."""
    def point_segment(x, a, b):
        ab = b - a
        t = np.clip(np.dot(x - a, ab) / np.dot(ab, ab), 0.0, 1.0)
        return float(np.hypot(*(a + t * ab - x)))

    return min(point_segment(p0, q0, q1), point_segment(p1, q0, q1),
               point_segment(q0, p0, p1), point_segment(q1, p0, p1))


def _line(p, q, m=_PIECE_SAMPLES):
    t = np.linspace(0.0, 1.0, m)[:, None]
    return p + t * (q - p)


def _bezier(p0, d0, p3, d3, m=_PIECE_SAMPLES):
    """Cubic Bezier from p0 (leaving along d0) to p3 (arriving along d3);
    the control arms are ``_WEB_TANGENT`` times the chord."""
    arm = _WEB_TANGENT * np.hypot(*(p3 - p0))
    p1 = p0 + arm * d0
    p2 = p3 - arm * d3
    t = np.linspace(0.0, 1.0, m)[:, None]
    return ((1 - t) ** 3) * p0 + 3 * ((1 - t) ** 2) * t * p1 + 3 * (1 - t) * t ** 2 * p2 + t ** 3 * p3


def _spline(points, d0, d1, m=_PIECE_SAMPLES):
    """Clamped cubic spline through ``points`` with unit end tangents."""
    pts = np.asarray(points, dtype=np.float64)
    knots = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    cs = CubicSpline(knots, pts, axis=0, bc_type=((1, np.asarray(d0)), (1, np.asarray(d1))))
    return cs(np.linspace(0.0, knots[-1], m))


def _arc(centre, w, n, u, m=_PIECE_SAMPLES):
    a = np.linspace(0.0, np.pi, m)[:, None]
    return centre + w * (np.cos(a) * n + np.sin(a) * u)


def _hand_pieces(pose: str):
    """The outline pieces (dense (m, 2) arrays in hand units, consecutive pieces
    sharing their end points) and their finger labels (-1 for palm and webs)."""
    base, tip, u, n, w = _fingers(pose)
    pieces, labels = [], []

    def finger(k, start=None):
        start = base[k] + w[k] * n[k] if start is None else start
        pieces.append(_line(start, tip[k] + w[k] * n[k]))  # right side, up
        pieces.append(_arc(tip[k], w[k], n[k], u[k]))  # tip
        pieces.append(_line(tip[k] - w[k] * n[k], base[k] - w[k] * n[k]))  # left side, down
        labels.extend([k, k, k])

    # The thumb's inner side starts _THUMB_WEB_OFFSET up from its base, so the
    # first web space stays open when the thumb is adducted.
    thumb_inner = base[0] + w[0] * n[0] + _THUMB_WEB_OFFSET * u[0]
    pinky_corner = base[4] + w[4] * n[4]
    pieces.append(_spline(np.vstack([_PALM_RIGHT, pinky_corner]), (1.0, 0.0), u[4]))
    labels.append(-1)
    for k in (4, 3, 2, 1):
        finger(k)
        nxt = k - 1
        end = thumb_inner if nxt == 0 else base[nxt] + w[nxt] * n[nxt]
        pieces.append(_bezier(base[k] - w[k] * n[k], -u[k], end, u[nxt]))
        labels.append(-1)
    finger(0, start=thumb_inner)
    thumb_corner = base[0] - w[0] * n[0]
    pieces.append(_spline(np.vstack([thumb_corner, _PALM_LEFT]), -u[0], (1.0, 0.0)))
    labels.append(-1)
    return pieces, np.asarray(labels)


def _arclength(points):
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])


@lru_cache(maxsize=None)
def _piece_shares():
    pieces, _ = _hand_pieces("open")
    lengths = np.array([_arclength(p)[-1] for p in pieces])
    return np.concatenate([[0.0], np.cumsum(lengths)]) / lengths.sum()


@lru_cache(maxsize=None)
def _hand_dense(pose: str):
    """Dense outline in hand units (x, y), its canonical parameter and labels."""
    pieces, labels = _hand_pieces(pose)
    starts = _piece_shares()
    pts, s, lab = [], [], []
    for i, piece in enumerate(pieces):
        cum = _arclength(piece)
        t = cum / cum[-1]
        pts.append(piece[:-1])
        s.append(starts[i] + t[:-1] * (starts[i + 1] - starts[i]))
        lab.append(np.full(len(piece) - 1, labels[i]))
    return np.vstack(pts), np.concatenate(s), np.concatenate(lab)


@lru_cache(maxsize=None)
def _hand_extent():
    """Bounding box (x_min, y_min, x_max, y_max) of every pose, in hand units."""
    boxes = np.array([[*_hand_dense(p)[0].min(axis=0), *_hand_dense(p)[0].max(axis=0)]
                      for p in HAND_POSES])
    return (boxes[:, 0].min(), boxes[:, 1].min(), boxes[:, 2].max(), boxes[:, 3].max())


def _hand_placement(shape, fill: float = 0.62):
    """Scale (px per hand unit) and centre (row, col) of the hand origin so that
    every pose fits in ``fill`` of the image, centred."""
    h, w = shape
    x0, y0, x1, y1 = _hand_extent()
    scale = fill * min(h / (y1 - y0), w / (x1 - x0))
    mid_x, mid_y = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    centre = ((h - 1) / 2.0 + scale * mid_y, (w - 1) / 2.0 - scale * mid_x)
    return scale, centre


def _to_rowcol(xy, scale, center):
    return np.column_stack([center[0] - scale * xy[:, 1], center[1] + scale * xy[:, 0]])


def hand_outline(pose: str = "open", *, n_nodes: int | None = None, scale: float = 1.0,
                 center=(0.0, 0.0), return_param: bool = False):
    """The outline of a hand with a palm and five fingers, without an image.

    The hand is built from a parametric skeleton (see the notes): a palm, and
    five capsule-shaped fingers (thumb included) rotated about their base by
    pose-dependent angles, :data:`HAND_POSES`.

    Parameters
    ----------
    pose : {"open", "closed", "spread"}, optional
        ``"open"``: fingers spread apart; ``"closed"``: fingers rotated toward
        each other, nearly touching; ``"spread"``: wider apart than ``"open"``.
    n_nodes : int, optional
        Resample to this many nodes evenly spaced in arc length.  By default
        about one node per unit of output length, and at least 256 nodes.
    scale : float, optional
        Output units per hand unit (the palm is about 1 hand unit wide and the
        hand about 2.1 units tall).
    center : tuple of float, optional
        ``(row, col)`` of the hand origin, the middle of the knuckle line
        (roughly the centre of the hand).
    return_param : bool, optional
        Also return the canonical parameter and finger label of every node.

    Returns
    -------
    contour : ndarray, shape (N, 2)
        ``(row, col)`` nodes, positively oriented, node 0 at the bottom centre
        of the palm.
    param : ndarray, shape (N,)
        Only if ``return_param``: canonical outline parameter in ``[0, 1)``.
        Equal values denote the same anatomical point in every pose.
    labels : ndarray of int, shape (N,)
        Only if ``return_param``: finger of each node, 0 (thumb) to 4 (pinky)
        as in :data:`HAND_FINGERS`, or -1 on the palm and the webs between
        fingers.

    Notes
    -----
    The outline is a chain of pieces: palm side, then for each finger from the
    pinky to the index its outer side, tip and inner side followed by the web
    to the next finger, then the thumb and the other palm side.  Finger sides
    are straight segments and tips half circles of pose-independent length;
    webs and palm sides are cubic curves whose end tangents follow the
    fingers.  Each piece owns a fixed share of the canonical parameter (its
    relative arc length in the ``"open"`` pose) and, within a piece, the
    parameter is proportional to arc length.
    """
    dense, s, lab = _hand_dense(pose)
    scale = float(scale)
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale}")
    rc = _to_rowcol(dense, scale, center)
    closed = np.vstack([rc, rc[:1]])
    cum = _arclength(closed)
    total = cum[-1]
    if n_nodes is None:
        n_nodes = max(int(round(total)), 256)
    n_nodes = int(n_nodes)
    if n_nodes < 3:
        raise ValueError(f"n_nodes must be at least 3, got {n_nodes}")
    t = np.arange(n_nodes) * (total / n_nodes)
    contour = np.column_stack([np.interp(t, cum, closed[:, 0]), np.interp(t, cum, closed[:, 1])])
    if not return_param:
        return contour
    s_closed = np.concatenate([s, [1.0]])
    param = np.interp(t, cum, s_closed)
    # Label of the dense segment each node falls on.
    seg = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(lab) - 1)
    return contour, param, lab[seg].copy()


def hand_pair(n_a: int = 67, n_b: int = 66, *, pose_a: str = "open", pose_b: str = "closed",
              scale: float | None = None, center=None):
    """Two hand outlines in different poses with their true node correspondence.

    Parameters
    ----------
    n_a, n_b : int, optional
        Number of nodes of the two contours (evenly spaced in arc length, node 0
        at the bottom centre of the palm).
    pose_a, pose_b : str, optional
        Poses of :data:`HAND_POSES`.
    scale, center : optional
        Placement as in :func:`hand_outline`; by default the placement used by
        :func:`hand` for a 256 x 256 image, so the contours overlay its images.

    Returns
    -------
    contour_a : ndarray, shape (n_a, 2)
    contour_b : ndarray, shape (n_b, 2)
    truth : ndarray of int, shape (n_a,)
        ``truth[i]`` is the node of ``contour_b`` corresponding to node ``i`` of
        ``contour_a``.

    Notes
    -----
    Both outlines come from the same parametric description (see
    :func:`hand_outline`), which gives every node a canonical parameter
    ``s`` in ``[0, 1)``: the same ``s`` is the same anatomical point (same
    finger, same side, same relative position along it) in every pose.
    ``truth[i]`` is the node of ``b`` whose parameter is cyclically nearest to
    that of node ``i`` of ``a``.  As ``s`` increases along both contours, the
    correspondence preserves the cyclic order of the nodes.
    """
    if scale is None or center is None:
        s0, c0 = _hand_placement((256, 256))
        scale = s0 if scale is None else scale
        center = c0 if center is None else center
    a, s_a, _ = hand_outline(pose_a, n_nodes=n_a, scale=scale, center=center, return_param=True)
    b, s_b, _ = hand_outline(pose_b, n_nodes=n_b, scale=scale, center=center, return_param=True)
    d = np.abs(s_a[:, None] - s_b[None, :])
    d = np.minimum(d, 1.0 - d)
    truth = np.argmin(d, axis=1).astype(np.intp)
    return a, b, truth


def hand(shape=(256, 256), *, pose: str = "open", bright: bool = True, noise: float = 0.0,
         contrast: float = 1.0, seed=0) -> SyntheticObject:
    """A hand with a palm and five separate fingers.

    The outline of :func:`hand_outline` is placed so that every pose fits in
    62 % of the image, centred, and rasterised with 5x5 super-sampling.

    Parameters
    ----------
    shape : tuple of int, optional
        Image shape ``(rows, cols)``; the hand scales with it.
    pose : {"open", "closed", "spread"}, optional
        At 256 x 256 (the hand about 160 px tall) the narrowest gap between
        adjacent long fingers is 7.6 px for ``"open"`` (at the finger bases;
        fingertips 18-21 px apart), 3 px for ``"closed"`` (near the tips) and
        7.6 px for ``"spread"`` (fingertips about 27 px apart).  Gaps scale
        with the image: below about 170 px a side, closed fingers are less
        than 2 px apart.
    bright : bool, optional
        Bright object on a dark background (default) or the reverse.
    noise : float, optional
        Standard deviation of additive Gaussian noise relative to the
        object/background step.
    contrast : float, optional
        Object/background step in units of 0.4.
    seed : int, optional
        Seed of the noise.

    Returns
    -------
    SyntheticObject
        ``outline`` is the 0.5 iso-contour (``skimage.measure.find_contours``)
        of the pixel coverage, resampled at ~1 px.
    """
    shape = _check_shape(shape)
    noise = _check_noise(noise)
    scale, centre = _hand_placement(shape)
    dense = _to_rowcol(_hand_dense(pose)[0], scale, centre)
    coverage = _polygon_coverage(dense, shape)
    outline = _coverage_outline(coverage)
    name = f"hand-{pose}-{'bright' if bright else 'dark'}"
    return _assemble(coverage, outline, name, bright=bright, contrast=contrast, noise=noise, seed=seed)


# --------------------------------------------------------------------------
# Warps and sample data
# --------------------------------------------------------------------------


def smooth_warp(contour, *, amplitude: float = 0.05, seed=0) -> np.ndarray:
    """A smooth non-rigid warp of a contour; node ``i`` maps to node ``i``.

    The displacement field is a sum of three random low-frequency plane waves
    per coordinate (wavelengths between the contour size and twice that),
    scaled so that its largest displacement over the nodes is
    ``amplitude * size`` (``size``: the larger side of the bounding box) and
    its gradient stays below 0.5, so the warp is a diffeomorphism of the plane
    and a simple contour stays simple.

    Parameters
    ----------
    contour : array_like, shape (N, 2)
        ``(row, col)`` nodes.
    amplitude : float, optional
        Largest displacement relative to the contour size.
    seed : int, optional
        Seed of the random field.

    Returns
    -------
    ndarray, shape (N, 2)
        The warped nodes; the true correspondence is the identity.
    """
    pts = np.asarray(contour, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"contour must be an (N, 2) array, got shape {pts.shape}")
    amplitude = float(amplitude)
    if amplitude < 0 or not np.isfinite(amplitude):
        raise ValueError(f"amplitude must be finite and non-negative, got {amplitude}")
    size = float(np.ptp(pts, axis=0).max())
    if amplitude == 0 or size == 0:
        return pts.copy()
    rng = np.random.default_rng(seed)
    centre = pts.mean(axis=0)
    x = (pts - centre) / size
    n_terms = 3
    disp = np.zeros_like(pts)
    grad = np.zeros((len(pts), 2, 2))
    for comp in range(2):
        for _ in range(n_terms):
            theta = rng.uniform(0, 2 * np.pi)
            freq = rng.uniform(0.5, 1.0) * np.array([np.cos(theta), np.sin(theta)])
            phase = rng.uniform(0, 2 * np.pi)
            coef = rng.normal()
            arg = 2 * np.pi * (x @ freq) + phase
            disp[:, comp] += coef * np.sin(arg)
            grad[:, comp, :] += coef * np.cos(arg)[:, None] * (2 * np.pi * freq / size)
    peak = np.hypot(disp[:, 0], disp[:, 1]).max()
    factor = amplitude * size / peak
    gnorm = np.linalg.norm(grad, ord=2, axis=(1, 2)).max() * factor
    if gnorm > 0.5:
        factor *= 0.5 / gnorm
    return pts + factor * disp


def sample_segmentation():
    """A 256 x 256 noisy image of an open hand and an initial contour.

    For napari's sample data: ``hand(pose="open", bright=True, noise=0.05)``.

    Returns
    -------
    image : ndarray of float64, shape (256, 256)
    init : ndarray of float64, shape (N, 2)
        The ``init_near`` contour, about 6 px outside the hand.
    """
    obj = hand((256, 256), pose="open", bright=True, noise=0.05, seed=0)
    return obj.image, obj.init_near


# --------------------------------------------------------------------------
# A deforming cell: a time-lapse with known membrane motion
# --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False, repr=False)
class SyntheticMovie:
    """A synthetic time-lapse of one object with its ground truth.

    Attributes
    ----------
    frames : ndarray of float64, shape (T, H, W)
        The images.
    masks : ndarray of bool, shape (T, H, W)
        The true object in each frame.
    outlines : ndarray of float64, shape (T, N, 2)
        The true border, ``N`` *material points*: point ``i`` of frame ``t``
        is where point ``i`` of frame 0 has moved (the truth of node
        correspondences), positively oriented.
    normal_velocity : ndarray of float64, shape (T, N)
        Each material point's displacement since the previous frame along its
        outward normal (px/frame; NaN at ``t = 0``).
    init : ndarray of float64, shape (M, 2)
        An initial contour on frame 0, about 4 px outside the object.
    name : str
    """

    frames: np.ndarray
    masks: np.ndarray
    outlines: np.ndarray
    normal_velocity: np.ndarray
    init: np.ndarray
    name: str

    def __repr__(self) -> str:
        return (f"SyntheticMovie(name={self.name!r}, frames={self.frames.shape}, "
                f"outline={self.outlines.shape[1]} material points)")


def _cell_outline(theta, t, n_frames, center, radius, drift, spin, waves, elongation=0.35):
    """Material points at body angles ``theta`` at time ``t``: an elongated
    body (so that its turning shows in its outline) whose radius is
    modulated by standing waves with slowly changing amplitudes, rotated by
    ``spin * t`` and carried by ``drift * t``."""
    phase = 2 * np.pi * t / n_frames
    r = radius / np.sqrt((np.cos(theta) / (1 + elongation)) ** 2 + (np.sin(theta) / (1 - elongation / 2)) ** 2)
    for k, amp, p, speed in waves:
        r += radius * amp * np.sin(speed * phase + p) * np.cos(k * theta + p)
    angle = theta + spin * t
    return np.column_stack([center[0] + drift[0] * t + r * np.sin(angle),
                            center[1] + drift[1] * t + r * np.cos(angle)])


def deforming_cell(n_frames: int = 30, shape=(160, 160), *, n_points: int = 720, noise: float = 0.1,
                   bright: bool = True, seed=0) -> SyntheticMovie:
    """A cell that drifts, turns slowly and protrudes and retracts, with known node motion.

    The membrane is a closed curve of ``n_points`` material points: at body
    angle ``theta`` its radius is that of an ellipse of axes ``1.35 R`` and
    ``0.82 R`` plus ``R sum_k a_k sin(w_k t + p_k) cos(k theta + p_k)``
    (standing waves of orders 3 to 5 whose amplitudes, up to 5 % of ``R``,
    rise and fall over the movie); the body turns by 0.4 degrees and drifts
    by about 0.4 px per frame. Each material point keeps its body angle, so
    the truth of correspondences and of normal velocity is known exactly,
    and the body is elongated so that its turning shows in its outline.

    Parameters
    ----------
    n_frames : int, optional
    shape : tuple of int, optional
        Frame shape ``(rows, cols)``, at least 96 x 96.
    n_points : int, optional
        Material points of the true outline.
    noise, bright, seed : optional
        As for :func:`blob`.

    Returns
    -------
    SyntheticMovie
    """
    shape = _check_shape(shape)
    if min(shape) < 96:
        raise ValueError(f"shape must be at least 96 x 96 for the cell to fit, got {shape}")
    noise = _check_noise(noise)
    n_frames = int(n_frames)
    if n_frames < 2:
        raise ValueError(f"n_frames must be at least 2, got {n_frames}")
    rng = np.random.default_rng(seed)
    radius = 0.2 * min(shape)
    drift = np.array([0.4, 0.24]) * min(shape) / 160  # px per frame
    center = np.array(shape, float) / 2 - drift * (n_frames - 1) / 2  # mid-movie at the centre
    spin = np.deg2rad(0.4)
    waves = [(k, rng.uniform(0.02, 0.05), rng.uniform(0, 2 * np.pi), rng.uniform(0.5, 1.5)) for k in (3, 4, 5)]
    theta = np.linspace(0, 2 * np.pi, int(n_points), endpoint=False)
    outlines = np.stack([_cell_outline(theta, t, n_frames, center, radius, drift, spin, waves)
                         for t in range(n_frames)])
    frames, masks = [], []
    for t in range(n_frames):
        coverage = _polygon_coverage(outlines[t], shape)
        masks.append(_clean_mask(coverage))
        frames.append(_render(coverage, bright=bright, contrast=1.0, noise=noise, seed=(seed, t)))
    velocity = np.full((n_frames, len(theta)), np.nan)
    for t in range(1, n_frames):
        normals = _outward(outlines[t])
        velocity[t] = ((outlines[t] - outlines[t - 1]) * normals).sum(1)
    return SyntheticMovie(
        frames=np.stack(frames), masks=np.stack(masks), outlines=outlines, normal_velocity=velocity,
        init=_init_near(masks[0], distance=4.0), name="deforming-cell")


def _outward(contour: np.ndarray) -> np.ndarray:
    from .core.contour import outward_normals

    return outward_normals(contour)

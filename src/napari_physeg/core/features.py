"""Image features that drive the physical contour: edges, distance, intensity.

The paper's segmentation forces read three images:

* an **edge map** from the Shen–Castan detector [1]_ (ISEF smoothing, zero
  crossings of the binary Laplacian image, adaptive gradient, hysteresis);
* the **chamfer distance** of every pixel to the nearest edge pixel;
* a **normalised intensity** image (robust min-max to [0, 1]).

:func:`compute_features` builds all of them at once from a 2D grey image;
the other public functions are its building blocks.

What a caller should know
-------------------------
* Of the two pixels straddling a zero crossing the bright-side one is
  marked: a bright object's edge lies on its outermost pixels, a dark
  object's on the background pixels around it (one pixel outside).
* Hysteresis seeds must beat both the ``high_quantile`` (default 0.95) of
  the candidates' strengths and a noise floor (four standard deviations of
  the noise left after smoothing, the noise being estimated from the
  image), and dominate their surroundings; chains extend down to
  ``min(low_ratio * high, 4 * floor)``; chains shorter than ``min_length``
  pixels are dropped and one-pixel spurs pruned. Pure noise and constant
  images yield no edges; an object far weaker than the strongest ones in
  the image, and not connected to them, may be missed.
* Percentiles and the noise level of images over 16384 pixels are
  estimated on a regular sub-grid of about that many pixels, for speed.

Boundary convention
-------------------
Everything here extends an image beyond its border by *half-sample symmetric*
reflection, ``... x1 x0 | x0 x1 ...`` (``np.pad(mode="symmetric")``,
``scipy.ndimage`` ``mode="reflect"``, ``cv2.BORDER_REFLECT``). Unlike the
whole-sample mirror it is defined for images one pixel wide and it keeps a
constant image constant.

References
----------
.. [1] J. Shen and S. Castan, "An optimal linear operator for step edge
       detection", CVGIP: Graphical Models and Image Processing 54(2),
       112-133, 1992. :DOI:`10.1016/1049-9652(92)90060-B`
.. [2] J. Immerkær, "Fast noise variance estimation", Computer Vision and
       Image Understanding 64(2), 300-302, 1996.
       :DOI:`10.1006/cviu.1996.0060`
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage as ndi
from scipy import signal

__all__ = [
    "isef_kernel",
    "isef_smooth",
    "shen_castan_edges",
    "chamfer_distance",
    "normalized_intensity",
    "FeatureImages",
    "compute_features",
]

#: Seeds of the hysteresis must exceed this many standard deviations of the
#: noise left in the smoothed image. On pure Gaussian noise the largest
#: adaptive gradient of ~10^5 candidates is below 3.5 sigma for b = 0.5 and
#: below 1 sigma for b >= 0.9 (any window 3..11), so 4 leaves noise without
#: seeds while a unit step (strength ~0.17 for b = 0.9, window 7) clears it
#: up to a noise sigma of ~1.5x its contrast.
_NOISE_FLOOR_SIGMAS = 4.0

#: A hysteresis seed must be at least this fraction of the strongest edge
#: strength within the ISEF's reach (see _shen_castan).
_SEED_DOMINANCE = 0.5

#: Hysteresis chains extend over candidates above this many noise floors
#: even where that is below ``low_ratio * high`` (see _shen_castan).
_CHAIN_FLOOR_FACTOR = 4.0

#: Contrast below this fraction of the image's magnitude is floating-point
#: round-off (e.g. ``smoothed - image`` of a constant image), never an edge.
_ROUNDOFF = 1e-9

#: Percentiles (and the noise median) are estimated on a regular sub-grid of
#: at most this many pixels: exact percentiles of a 512x512 image cost ~5 ms
#: each here, a sizeable part of compute_features, for no visible change.
_MAX_SAMPLES = 1 << 14


# --------------------------------------------------------------------------
# validation helpers


def _check_b(b) -> float:
    if isinstance(b, (bool, np.bool_)) or not isinstance(b, numbers.Real):
        raise ValueError(f"b must be a real number in (0, 1), got {b!r}")
    b = float(b)
    if not 0.0 < b < 1.0:
        raise ValueError(
            f"b must be in (0, 1) (0: no smoothing, towards 1: more smoothing), got {b!r}"
        )
    return b


def _check_fraction(value, name: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number in (0, 1], got {value!r}")
    value = float(value)
    if not 0.0 < value <= 1.0:
        raise ValueError(f"{name} must be in (0, 1], got {value!r}")
    return value


def _check_window(window) -> int:
    if isinstance(window, (bool, np.bool_)) or not isinstance(window, numbers.Integral):
        raise ValueError(f"window must be an odd integer >= 3, got {window!r}")
    window = int(window)
    # An odd window is centred on its pixel; cv2 would shift an even one.
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 3, got {window!r}")
    return window


def _check_min_length(value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral) or value < 1:
        raise ValueError(f"min_length must be a positive integer (pixels), got {value!r}")
    return int(value)


def _check_noise(noise) -> float | None:
    if noise is None:
        return None
    if isinstance(noise, (bool, np.bool_)) or not isinstance(noise, numbers.Real) or not (
            np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise must be a finite non-negative number (the noise's standard deviation, in the "
                         f"image's units) or None to estimate it, got {noise!r}")
    return float(noise)


def _masked_as_missing(image):
    """``image``, or, when it is a numpy masked array with masked pixels, a
    float64 copy with NaN there: a mask marks pixels with no data, which NaN
    stands for everywhere in the core (np.asarray drops the mask silently, and
    the masked pixels' stored values, often 0 or a fill value, were read as
    image)."""
    if np.ma.isMaskedArray(image) and np.ma.is_masked(image):
        return np.ma.filled(image.astype(np.float64), np.nan)
    return image


def _without_missing(image, *, name: str = "image") -> tuple[np.ndarray, np.ndarray | None]:
    """``image`` with its NaN pixels (no data) filled, and where they were.

    NaN marks pixels nothing was measured at: the margin a registration or a
    stage-drift correction leaves, a masked region. Each takes the value of
    its mirror image across the edge of the nearest measured pixel (that
    pixel's own, where the mirror image is not measured either), as the
    filters treat the image's sides: their border makes no edge of its own
    (zeros would: a dark frame around a bright field), and an object they
    cut does not stream into them (the nearest pixel's value would: the
    rings the drawing's levels are read on took its streaks for the object:
    real cases cut across their middle, ``benchmarks/scale.py --cut``, ended
    at IoU 0.780 with the truth against 0.823 on the image cropped there,
    0.812 mirrored). The caller keeps the contour out of them, as out of the
    image (``missing``).

    Parameters
    ----------
    image : (H, W) array_like
    name : str, optional
        The image's name in error messages.

    Returns
    -------
    filled : (H, W) ndarray
        ``image`` itself when it has no NaN pixel, else a float64 copy filled.
    missing : (H, W) ndarray of bool or None
        The NaN pixels; None when there are none.

    Raises
    ------
    ValueError
        If every pixel is NaN.
    """
    arr = np.asarray(image)
    if arr.dtype.kind != "f":
        return arr, None
    missing = np.isnan(arr)
    if not missing.any():
        return arr, None
    if missing.all():
        raise ValueError(f"{name} holds NaN pixels only: there is nothing to segment")
    nearest = ndi.distance_transform_edt(missing, return_distances=False, return_indices=True)
    # Mirrored about the measured pixels' outer edge (the edge pixel repeated,
    # as OpenCV's BORDER_REFLECT; about its centre, the mirrored object met
    # itself at a neck there and its region lost that pixel), and again about
    # the image's sides when a wide margin's mirror image lies beyond them.
    mirrored = tuple(_folded(2 * q - p + np.sign(p - q), n)
                     for q, p, n in zip(nearest, np.indices(arr.shape), arr.shape))
    filled = np.where(missing, arr[mirrored], arr)
    filled = np.where(np.isnan(filled), arr[tuple(nearest)], filled)
    return filled.astype(np.float64), missing


#: A pixel is a spike (a hot or dead pixel of the camera, a cosmic ray) when
#: it lies beyond all 8 of its neighbours by more than SPIKE_RATIO times their
#: own spread, or than that many times the spread of most pixels' neighbours
#: (the median: the noise's, where the ground is flat; an 8-bit movie's dark
#: ground holds single pixels one grey level off). An optical image is sampled
#: finer than its blur: the peak of a spot blurred over even half a pixel
#: (Gaussian sigma 0.5 px) rises above its nearest neighbours by 7.4 times
#: their spread, and a wider spot by less.
SPIKE_RATIO = 10.0


def _without_spikes(image: np.ndarray) -> np.ndarray:
    """``image`` (2D float64, as :func:`_as_image` checks and casts it) with
    its single-pixel spikes (see SPIKE_RATIO) replaced by the median of their
    8 neighbours; ``image`` itself when it has none.

    Three hot pixels within 15 px of a nucleus (50 times the image's
    brightest) took a drawing's reading of its levels in 10 of 1128 real
    runs, one read as a spot drawn around (IoU 0.84 -> 0.00): the drawing's
    centre is read on few pixels, more so on a magnified view, where a hot
    pixel becomes a blob. Taken out, 2 runs remain, where two of them touch
    (each has the other for a neighbour: no spike by this rule).
    """
    if min(image.shape) < 3:  # no pixel with 8 neighbours
        return image
    # Found in single precision (OpenCV's morphology is 3 times faster on it;
    # a spike stands out by far more than its rounding), mended in double.
    single = image.astype(np.float32)
    ring = np.ones((3, 3), np.uint8)
    ring[1, 1] = 0
    highest = cv2.dilate(single, ring, borderType=cv2.BORDER_REFLECT)
    lowest = cv2.erode(single, ring, borderType=cv2.BORDER_REFLECT)
    beyond = highest - lowest
    typical = float(np.median(_subsample(beyond)))
    np.maximum(beyond, max(typical, 1e-6 * float(np.abs(single).max())), out=beyond)
    beyond *= SPIKE_RATIO
    spikes = (single - highest) > beyond
    spikes |= (lowest - single) > beyond
    if not spikes.any():
        return image
    rows, cols = np.nonzero(spikes)
    padded = np.pad(image, 1, mode="symmetric")
    neighbours = np.stack([padded[rows + 1 + dr, cols + 1 + dc]
                           for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc])
    cleaned = image.copy()
    cleaned[rows, cols] = np.median(neighbours, axis=0)
    return cleaned


def _folded(index: np.ndarray, n: int) -> np.ndarray:
    """Indices folded into ``[0, n)`` by reflection about the sides (edge pixels repeated)."""
    index = np.mod(index, 2 * n)
    return np.where(index < n, index, 2 * n - 1 - index)


def _as_image(image, *, name: str = "image", min_size: int = 1) -> np.ndarray:
    """Validate a 2D real image and return it as float64 (a copy if cast)."""
    return _check_image(image, name=name, min_size=min_size).astype(np.float64, copy=False)


def _check_2d(arr: np.ndarray, name: str = "image") -> None:
    """Raise unless ``arr`` is 2D, saying how to get a 2D image from an RGB(A) image or a stack."""
    if arr.ndim == 2:
        return
    if arr.ndim == 3 and arr.shape[-1] in (3, 4):
        kind = "RGB" if arr.shape[-1] == 3 else "RGBA"
        colours = name if kind == "RGB" else f"{name}[..., :3]"
        raise ValueError(
            f"{name} has shape {arr.shape}: it looks like an {kind} image; pass one "
            f"channel (e.g. {name}[..., 0]) or convert it to grey, e.g. skimage.color.rgb2gray({colours}); "
            f"for a brightfield stain, the stain's own channel (e.g. skimage.color.rgb2hed({colours})[..., 0], "
            "hematoxylin)"
        )
    if arr.ndim == 3 and arr.shape[-1] == 1 < min(arr.shape[:2]):
        raise ValueError(f"{name} has shape {arr.shape}: one channel, last; pass {name}[..., 0]")
    if arr.ndim == 3:
        raise ValueError(
            f"{name} has shape {arr.shape}: it is a 3D stack; pass a single 2D "
            f"slice, e.g. {name}[0]"
        )
    raise ValueError(f"{name} must be a 2D (rows, cols) array, got shape {arr.shape}")


def _check_image(image, *, name: str = "image", min_size: int = 1) -> np.ndarray:
    """Validate a 2D finite real image; return it as an array of its own dtype."""
    arr = np.asarray(image)
    if arr.dtype.kind == "c":
        raise ValueError(
            f"{name} has complex dtype {arr.dtype}: pass a real image, "
            f"e.g. np.abs({name}) or {name}.real"
        )
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"{name} must have a real numeric dtype, got {arr.dtype}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    _check_2d(arr, name)
    if min(arr.shape) < min_size:
        raise ValueError(
            f"{name} is too small (shape {arr.shape}): need at least "
            f"{min_size}x{min_size} pixels"
        )
    if arr.dtype.kind in "bui":
        return arr  # integers are finite
    finite = np.isfinite(arr)
    if not finite.all():
        n_nan = int(np.isnan(arr).sum())
        if n_nan:
            raise ValueError(
                f"{name} contains {n_nan} NaN pixels: fill or mask them first, "
                f"e.g. np.nan_to_num({name})"
            )
        raise ValueError(
            f"{name} contains {int((~finite).sum())} infinite pixels: clip or replace "
            f"them first, e.g. np.nan_to_num({name}, posinf=..., neginf=...)"
        )
    return arr


def _subsample(x: np.ndarray) -> np.ndarray:
    """A regular sub-grid of ``x`` with at most ~``_MAX_SAMPLES`` pixels."""
    step = int(np.ceil(np.sqrt(x.size / _MAX_SAMPLES)))
    return x if step <= 1 else x[::step, ::step]


# --------------------------------------------------------------------------
# ISEF smoothing


def isef_kernel(b, radius) -> np.ndarray:
    """The 1D Infinite Symmetric Exponential Filter, truncated.

    ``f[n] = (1 - b) / (1 + b) * b**|n|`` for ``n = -radius..radius``; the
    untruncated kernel sums to 1.

    Parameters
    ----------
    b : float
        Smoothing parameter in (0, 1); larger is smoother.
    radius : int
        Half-width of the returned kernel (>= 0).

    Returns
    -------
    kernel : ndarray of float64, shape (2 * radius + 1,)

    Examples
    --------
    >>> isef_kernel(0.5, 1)
    array([0.16666667, 0.33333333, 0.16666667])
    """
    b = _check_b(b)
    if (
        isinstance(radius, (bool, np.bool_))
        or not isinstance(radius, numbers.Integral)
        or radius < 0
    ):
        raise ValueError(f"radius must be a non-negative integer, got {radius!r}")
    n = np.arange(-int(radius), int(radius) + 1)
    with np.errstate(under="ignore"):
        return (1.0 - b) / (1.0 + b) * b ** np.abs(n)


def _steady_state_weights(n: int, b: float) -> np.ndarray:
    """Weights that give the causal recursion's state before sample 0.

    The state is the infinite sum ``b1 * sum_k>=1 b**(k-1) x[-k]`` over the
    half-sample symmetric extension. That extension is periodic (period
    ``2n``), so the sum folds onto the ``n`` real samples with weights
    ``(b**j + b**(2n-1-j)) / (1 - b**(2n))``: exact (no truncated tail at
    all) and much cheaper than filtering a pad that, for b -> 1, would be
    longer than the image.
    """
    j = np.arange(n)
    with np.errstate(under="ignore"):
        return (b**j + b ** (2 * n - 1 - j)) / (1.0 - b ** (2 * n))


def _causal(x: np.ndarray, w: np.ndarray, b: float, b1: float, axis: int) -> np.ndarray:
    """``A[i] = b A[i-1] + b1 x[i]`` along ``axis``, started in steady state."""
    # lfilter's state is what the recursion adds to b1 * x[0], i.e. b * A[-1].
    if axis == 0:
        zi = (b * b1) * (w @ x)[np.newaxis, :]
    else:
        zi = (b * b1) * (x @ w)[:, np.newaxis]
    out, _ = signal.lfilter([b1], [1.0, -b], x, axis=axis, zi=zi)
    return out


#: Elements per block of the recursive passes (256 KiB of float64): the
#: blocks stay in cache and their temporaries are recycled by the allocator,
#: where whole-image temporaries each cost fresh pages (on a 512x512 image
#: that doubled the filter's run time).
_BLOCK = 1 << 15


def _isef_pass(src: np.ndarray, dst: np.ndarray, b: float, b1: float, axis: int) -> None:
    """One 1D ISEF pass of ``src`` along ``axis`` into ``dst`` (may be ``src``)."""
    flip = (slice(None), slice(None, None, -1)) if axis == 1 else (slice(None, None, -1),)
    w = _steady_state_weights(src.shape[axis], b)
    # Blocks of whole lines across the other axis; a block is filtered
    # completely before it is written, so dst may alias src.
    n_lines = src.shape[1 - axis]
    step = max(1, _BLOCK // src.shape[axis])
    for start in range(0, n_lines, step):
        block = slice(start, start + step)
        lines = (slice(None), block) if axis == 0 else (block,)
        x = src[lines]
        out = _causal(x, w, b, b1, axis)
        # The anti-causal pass is the causal one on the reversed signal. With
        # gain b1 instead of the paper's b2 = b * b1 it includes the centre
        # sample, D[i] = b1 * sum_k>=0 b**k x[i+k] = B[i+1] + b1 x[i], so
        # y = A + B[i+1] = A + D - b1 x.
        anti = _causal(x[flip], w, b, b1, axis)
        out += anti[flip]
        out -= np.multiply(x, b1, out=anti)
        dst[lines] = out


def _isef(x: np.ndarray, b: float, out: np.ndarray | None = None) -> np.ndarray:
    """ISEF of a validated float64 2D array (rows, then columns)."""
    b1 = (1.0 - b) / (1.0 + b)
    y = np.empty(x.shape) if out is None else out  # C order: cv2 needs it
    _isef_pass(x, y, b, b1, axis=1)
    _isef_pass(y, y, b, b1, axis=0)
    return y


def isef_smooth(image, b=0.9) -> np.ndarray:
    """Smooth with Shen and Castan's Infinite Symmetric Exponential Filter.

    The separable 2D filter with 1D kernel ``f[n] = (1-b)/(1+b) * b**|n|``
    (see :func:`isef_kernel`) is applied along rows, then columns, each by
    the recursive form of [1]_: with ``b1 = (1-b)/(1+b)`` and ``b2 = b b1``,
    a causal pass ``A[i] = b A[i-1] + b1 x[i]``, an anti-causal pass
    ``B[i] = b B[i+1] + b2 x[i]``, and ``y[i] = A[i] + B[i+1]``. Cost does
    not depend on ``b``.

    The image is extended by half-sample symmetric reflection
    (``np.pad(mode="symmetric")``, i.e. ``scipy.ndimage`` ``mode="reflect"``),
    repeated as often as needed; the recursions start in the exact steady
    state of that infinite extension, so the result equals the convolution
    with the untruncated kernel (to round-off).

    Parameters
    ----------
    image : (M, N) array_like
        Real 2D image.
    b : float, optional
        Smoothing parameter in (0, 1); larger is smoother (the kernel's
        standard deviation is ``sqrt(2 b) / (1 - b)`` pixels: 13.4 px at the
        default 0.9).

    Returns
    -------
    smoothed : (M, N) ndarray of float64
        Same mean as ``image``; linear in ``image``.

    Raises
    ------
    ValueError
        If ``b`` is not in (0, 1) or ``image`` is not a finite real 2D array.
    """
    b = _check_b(b)
    return _isef(_as_image(image), b)


# --------------------------------------------------------------------------
# Shen–Castan edges


def _noise_sigma(image: np.ndarray) -> float:
    """Robust standard deviation of the image noise (Immerkær [2]_).

    The 3x3 operator ``[1, -2, 1] x [1, -2, 1]`` cancels planes and, nearly,
    smooth shading, and multiplies white noise's standard deviation by 6.
    The median of its magnitude ignores the thin band around edges. With
    quantised, mostly flat images the median can be 0; the (edge-biased,
    hence conservative) mean absolute value is used then. Evaluated on the
    regular sub-grid of :func:`_subsample`'s spacing, borders excluded.
    """
    rows, cols = image.shape
    if rows < 3 or cols < 3:
        return 0.0
    step = int(np.ceil(np.sqrt(image.size / _MAX_SAMPLES)))
    # Second difference down the columns on the sub-grid's rows only, then
    # along the rows on its columns: small temporaries.
    t = image[0 : rows - 2 : step] - 2.0 * image[1 : rows - 1 : step]
    t += image[2:rows:step]
    resp = t[:, 0 : cols - 2 : step] - 2.0 * t[:, 1 : cols - 1 : step]
    resp += t[:, 2:cols:step]
    np.abs(resp, out=resp)
    med = float(np.median(resp))
    if med > 0:
        return 1.4826 * med / 6.0
    return float(np.sqrt(np.pi / 2.0) * resp.mean() / 6.0)


def _rounding_sigma(image: np.ndarray) -> float:
    """The standard deviation rounding to ``image``'s levels adds (its
    least step between levels, over the square root of 12; 0 for levels
    that run on), measured on the sub-grid of :func:`_subsample`.

    Where the noise is less than a level (an 8-bit image's flat ground,
    which rounds to one level), smoothing does not average it away: a true
    level between two rounds to the same one over a whole region."""
    levels = np.unique(_subsample(np.asarray(image)))
    return float(np.diff(levels).min()) / np.sqrt(12.0) if levels.size > 1 else 0.0


def _quantile_above(strength, cand, q, floor) -> float:
    """``np.quantile(strength[cand], q)`` if it exceeds ``floor``, else ``floor``.

    Only the candidates above the floor are gathered and ranked: on a noisy
    image they are a few percent of the pixels, while gathering all
    candidates (~40 %) through a boolean mask costs more than the rest of
    the edge detector.
    """
    n_cand = int(np.count_nonzero(cand))
    above = strength[strength > floor]  # non-candidates hold 0 <= floor
    rank = q * (n_cand - 1)  # numpy's default "linear" quantile
    lo = int(np.floor(rank))
    hi = min(lo + 1, n_cand - 1)
    n_below = n_cand - above.size
    if lo < n_below:
        return floor  # the quantile's lower neighbour is <= floor
    lo -= n_below
    hi -= n_below
    part = np.partition(above, [lo, hi]) if above.size > 1 else above
    return float(part[lo] + (rank - np.floor(rank)) * (part[hi] - part[lo]))


def _shen_castan(
    image, smoothed, b, window, high_quantile, low_ratio, min_length, *, overwrite=False, work=None, noise=None
):
    """Edges and strengths from a validated image and its ISEF smoothing.

    With ``overwrite`` the image's buffer is reused for the strengths;
    ``work``, if given, is a scratch float64 array of the image's shape;
    ``noise``, if given, the standard deviation of the image's noise.
    """
    shape = image.shape
    no_edges = np.zeros(shape, dtype=bool)
    scale = max(abs(float(image.max())), abs(float(image.min())))
    if float(smoothed.max() - smoothed.min()) <= _ROUNDOFF * scale:
        return no_edges, np.zeros(shape, dtype=np.float64)  # constant image: the BLI would be round-off noise
    # Binary Laplacian image: smoothed - image approximates the Laplacian and
    # is positive on the dark side of a step.
    bli = smoothed > image
    cand = _zero_crossings(bli, smoothed)
    if not cand.any():
        return no_edges, np.zeros(shape, dtype=np.float64)
    noise_sigma = _noise_sigma(image) if noise is None else noise  # before image may be overwritten
    strength = _adaptive_gradient(image, smoothed, bli, cand, window, overwrite, work)
    # Hysteresis thresholds. The quantile of the candidates alone picks noise
    # when most candidates are noise (a noisy image has zero crossings at
    # ~40 % of its pixels), so seeds must also beat a noise floor: a multiple
    # of the noise's standard deviation after ISEF smoothing (white noise's
    # std is multiplied by sum(f**2) = (1-b)(1+b^2)/(1+b)^3 in 2D), and
    # round-off relative to the image's magnitude.
    gain = (1.0 - b) * (1.0 + b * b) / (1.0 + b) ** 3
    floor = max(_NOISE_FLOOR_SIGMAS * gain * noise_sigma, _ROUNDOFF * scale)
    high = max(_quantile_above(strength, cand, high_quantile, floor), floor)
    if float(strength.max()) < high:
        return no_edges, strength
    # Chains extend over candidates >= low_ratio * high, or over any that is
    # clearly significant (_CHAIN_FLOOR_FACTOR noise floors): on a clean
    # image the weak parts of a border (thin protrusions, which the ISEF
    # flattens) stay attached to its strong parts; on a noisy one the
    # threshold rises with the noise.
    low = min(low_ratio * high, _CHAIN_FLOOR_FACTOR * floor)
    seeds = _dominant_seeds(strength, high, b)
    return _chains(strength >= low, seeds, min_length), strength  # (off the candidates strength is 0 < low)


def _zero_crossings(bli: np.ndarray, smoothed: np.ndarray) -> np.ndarray:
    """The edge candidates: the bright side of each zero crossing of the
    binary Laplacian image ``bli`` between 4-neighbours (pairs (p, right)
    and (p, below)) across which ``smoothed`` rises toward it.

    Shen-Castan's false-crossing test: going from the BLI=1 (dark) pixel to
    the BLI=0 (bright) pixel the smoothed image must rise strictly;
    otherwise it is a ripple of the Laplacian, not an edge. (Requiring the
    rise to peak at the crossing, as a Laplacian zero crossing should, was
    tried and rejected: with the wide ISEF the peak of a curved edge's rise
    is displaced from the sharp step that sets the BLI, and most of a disc's
    border failed.) Of each valid pair the BLI=0 pixel, the bright side
    (smoothed <= image), is marked, so the edges of a bright object lie on
    its outermost pixels and those of a dark object on the background's
    innermost ones.
    """
    cand = np.zeros(bli.shape, dtype=bool)
    pairs = (
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    )
    for first, second in pairs:
        bli_a, bli_b = bli[first], bli[second]
        s_a, s_b = smoothed[first], smoothed[second]
        cand[second] |= bli_a & ~bli_b & (s_b > s_a)  # 1 -> 0, rising: mark second
        cand[first] |= bli_b & ~bli_a & (s_b < s_a)  # 0 -> 1, falling: mark first
    return cand


def _adaptive_gradient(image, smoothed, bli, cand, window: int, overwrite: bool, work) -> np.ndarray:
    """Each candidate's strength: the difference of the smoothed image's
    means over the BLI=1 and BLI=0 pixels of its ``window`` x ``window``
    neighbourhood (0 off the candidates ``cand``).

    From box filters: with k the count of BLI=1 pixels among the window's
    N, m the mean of smoothed and m1 the mean of smoothed*BLI (f = k/N),
    mean1 - mean0 = m1 / f - (m - m1) / (1 - f) = N (N m1 - k m) / (k (N - k)).
    Both classes are present in any candidate's 3x3 neighbourhood, so there
    k (N - k) >= N - 1; elsewhere the result is discarded. Computed on the
    whole image, in place (in ``image``'s buffer with ``overwrite``, and in
    ``work`` if given), the count in uint8 (for windows up to 15): masked
    indexing and fresh whole-image temporaries cost more than arithmetic.
    """
    ksize = (window, window)
    n_win = float(window * window)
    bt = cv2.BORDER_REFLECT
    depth = cv2.CV_8U if n_win < 256 else cv2.CV_32F  # exact counts either way
    count = cv2.boxFilter(bli.view(np.uint8), depth, ksize, normalize=False, borderType=bt)
    strength = np.multiply(smoothed, bli, out=image if overwrite else None)
    cv2.boxFilter(strength, -1, ksize, dst=strength, borderType=bt)
    mean = cv2.boxFilter(smoothed, -1, ksize, dst=work, borderType=bt)
    strength *= n_win
    mean *= count
    strength -= mean
    np.abs(strength, out=strength)
    np.subtract(n_win, count, out=mean)
    mean *= count
    np.maximum(mean, n_win - 1.0, out=mean)
    strength /= mean
    strength *= n_win
    strength *= cand
    return strength


def _dominant_seeds(strength: np.ndarray, high: float, b: float) -> np.ndarray:
    """The chains' seeds: candidates at least ``high`` strong and at least
    half (_SEED_DOMINANCE) the strongest strength within the ISEF's reach,
    2 / (1 - b) px.

    Noise flips the Laplacian's sign on the long flanks of a smoothed edge,
    and there the adaptive gradient is sizeable (the flank is steep) but well
    below the edge's own; on a small object in a large noisy frame such
    crossings outnumber its border and reach the quantile. (In units of
    ``high`` and float32: a maximum needs no precision, and cv2 dilates
    float32 8x faster than float64.)
    """
    relative = np.empty(strength.shape, dtype=np.float32)
    np.multiply(strength, 1.0 / high, out=relative, casting="same_kind")
    reach = min(int(np.ceil(2.0 / (1.0 - b))), max(strength.shape))
    box = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * reach + 1, 2 * reach + 1))
    local_max = cv2.dilate(relative, box, borderType=cv2.BORDER_REFLECT)
    local_max *= _SEED_DOMINANCE
    return (strength >= high) & (relative >= local_max)


def _chains(weak: np.ndarray, seeds: np.ndarray, min_length: int) -> np.ndarray:
    """The 8-connected chains of ``weak`` candidates that hold a seed and
    at least ``min_length`` pixels, their spurs pruned.

    (skimage's apply_hysteresis_threshold labels 4-connected components,
    which breaks the staircase of a diagonal edge into single pixels.)
    Short chains are dropped: Laplacian sign flips caused by noise on the
    long flanks of a smoothed edge have a strong adaptive gradient (the
    flank is steep) but come as isolated pixels or pairs. (Sizes from the
    few weak pixels: cv2's WithStats variant costs 5x the labelling.)
    """
    n_labels, labels = cv2.connectedComponents(weak.view(np.uint8), connectivity=8)
    keep = np.zeros(n_labels, dtype=bool)
    keep[labels[seeds]] = True
    keep &= np.bincount(labels[weak], minlength=n_labels) >= min_length
    keep[0] = False
    return _prune_spurs(keep[labels], _SPUR_LENGTH)


#: Branches of up to this many pixels hanging off an edge chain are pruned.
#: (2 also removes the rarer 2-pixel spurs but opens more gaps in noisy
#: edges: chains broken by noise lose pixels at every new end.)
_SPUR_LENGTH = 1


def _prune_spurs(edges: np.ndarray, length: int) -> np.ndarray:
    """Remove the end pixels of 8-connected chains, ``length`` times.

    Where the Laplacian is weak, e.g. on the background just outside the
    corner of a dark object, a noise crossing next to the edge joins it and
    another one a pixel further out: a short spur pointing away from the
    border. Closed contours have no end pixels and keep everything but their
    spurs; open chains lose ``length`` pixels at each end.
    """
    kernel = np.ones((3, 3), dtype=np.float32)
    kernel[1, 1] = 0.0
    for _ in range(length):
        neighbours = cv2.filter2D(
            edges.view(np.uint8), cv2.CV_8U, kernel, borderType=cv2.BORDER_CONSTANT
        )
        tips = edges & (neighbours == 1)
        if not tips.any():
            break
        edges &= ~tips
    return edges


def shen_castan_edges(
    image,
    *,
    b=0.9,
    window=7,
    high_quantile=0.95,
    low_ratio=0.5,
    min_length=8,
    return_strength=False,
    noise=None,
):
    """Shen–Castan edge detector.

    1. Smooth with the ISEF (:func:`isef_smooth`).
    2. Binary Laplacian image ``BLI = smoothed > image``.
    3. Candidates: zero crossings of the BLI between 4-neighbours where the
       smoothed image rises strictly from the BLI=1 to the BLI=0 pixel
       (Shen and Castan's false-zero-crossing test). Of each crossing the
       **BLI=0 pixel** (``smoothed <= image``, the bright side) is marked.
    4. Strength (adaptive gradient): ``|mean(smoothed | BLI=1) -
       mean(smoothed | BLI=0)|`` over the ``window x window`` window
       centred on the candidate.
    5. Hysteresis on 8-connected chains of candidates. Seeds have strength
       ``>= high = max(quantile(strengths, high_quantile), floor)`` and at
       least half the strongest strength within ``2 / (1 - b)`` px;
       chains extend over strength ``>= min(low_ratio * high, 4 * floor)``;
       chains of fewer than ``min_length`` pixels are dropped.
    6. One-pixel spurs are pruned: every chain end pixel is removed once
       (closed contours have none; open chains get one pixel shorter at
       each end).

    The **noise floor** is ``4 * sigma * (1-b)(1+b^2)/(1+b)^3``: four
    standard deviations of the image noise left after smoothing, with the
    noise ``sigma`` estimated robustly from the image (Immerkær's operator,
    median). Pure noise therefore yields no seeds, and the chains' threshold
    follows the noise: on a clean image weak parts of a border (thin
    protrusions, which the ISEF flattens) stay attached to its strong
    parts. The **seed dominance** rule removes the other source of false
    edges: noise flips the Laplacian's sign on the long flanks of a
    smoothed edge, several pixels off it, where the adaptive gradient is
    sizeable (the flank is steep) but well below the edge's own; on a small
    object in a large noisy frame such crossings outnumber its border and
    reach the quantile. A constant image, or one whose contrast is at
    round-off level (1e-9 of its magnitude), yields no edges. Because seeds
    come from a quantile, an object much weaker than the strongest ones in
    the image and not connected to them may be missed.

    Parameters
    ----------
    image : (M, N) array_like
        Real 2D grey image. Thresholds are relative, so its scale and offset
        do not matter.
    b : float, optional
        ISEF smoothing parameter in (0, 1); larger suppresses more noise and
        finds fewer, smoother edges.
    window : int, optional
        Odd side of the adaptive-gradient window (>= 3).
    high_quantile : float, optional
        Quantile, in (0, 1], of the candidates' strengths used as the high
        hysteresis threshold (unless below the noise floor). With the
        default, 0.95, 16 of the 24 coins of ``skimage.data.coins`` are
        outlined, and the fingers of a noisy hand; 0.99 outlines 6 coins
        and drops the fingers. The noise rules above keep 0.95 as robust.
    low_ratio : float, optional
        Low threshold as a fraction, in (0, 1], of the high one (capped at
        four noise floors, see above).
    min_length : int, optional
        Fewest pixels in a kept chain. Noise flips the Laplacian's sign on
        the steep flanks of a smoothed edge, a few pixels off it, and those
        crossings have a strong adaptive gradient but come as isolated pixels
        or pairs; 1 keeps them.
    return_strength : bool, optional
        Also return the adaptive gradient of every candidate.
    noise : float, optional
        Standard deviation of the image's noise, when the caller has measured
        it already; estimated from the image (Immerkær's operator, see above)
        when None.

    Returns
    -------
    edges : (M, N) ndarray of bool
        One-pixel-wide edges.
    strength : (M, N) ndarray of float64
        Only if ``return_strength``: adaptive gradient at the candidates,
        0 elsewhere, in the image's units.

    Raises
    ------
    ValueError
        If the image is not a finite real 2D array or a parameter is out of
        range.
    """
    b = _check_b(b)
    window = _check_window(window)
    high_quantile = _check_fraction(high_quantile, "high_quantile")
    low_ratio = _check_fraction(low_ratio, "low_ratio")
    min_length = _check_min_length(min_length)
    noise = _check_noise(noise)
    image = _as_image(image)
    edges, strength = _shen_castan(
        image, _isef(image, b), b, window, high_quantile, low_ratio, min_length, noise=noise
    )
    return (edges, strength) if return_strength else edges


# --------------------------------------------------------------------------
# distance and intensity


def chamfer_distance(edges) -> np.ndarray:
    """Distance of every pixel to the nearest edge pixel, in pixels.

    OpenCV's 5x5 chamfer metric (``cv2.DIST_L2`` with ``cv2.DIST_MASK_5``:
    steps 1, 1.4 and 2.1969), within ~2 % of the Euclidean distance and
    exactly 0 on the edges.

    Parameters
    ----------
    edges : (M, N) array_like
        Edge map; non-zero (or True) pixels are edges.

    Returns
    -------
    distance : (M, N) ndarray of float64
        If there is no edge at all, every pixel holds the image diagonal
        ``hypot(M, N)``, finite and larger than any real distance.
    """
    return _chamfer(_as_image(edges, name="edges") != 0)


def _chamfer(edges: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    if out is None:
        out = np.empty(edges.shape, dtype=np.float64)
    if not edges.any():
        # cv2 would return an arbitrary large value; the diagonal is finite
        # and still beyond any real distance.
        out.fill(float(np.hypot(*edges.shape)))
        return out
    # cv2 measures the distance of non-zero pixels to the nearest zero one.
    dist = cv2.distanceTransform((~edges).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    np.copyto(out, dist)
    return out


#: A sparse field: its few objects (spots over 2 % of the view or less)
#: set no percentile; the 99th (1st) lies below (above) the level of most of
#: their pixels, on their rims. The pixels beyond SPARSE_TAIL noise standard
#: deviations of the median are the objects' when there are at least
#: SPARSE_LEAST of them, at a median twice as far (spots that stand clear of
#: the noise): then the range reaches their SPARSE_QUANTILE. (Spots within 8
#: deviations keep the clip: it flattens their noise, and their mid-level
#: lies near it anyway.)
SPARSE_TAIL = 4.0
SPARSE_LEAST = 8
SPARSE_QUANTILE = 0.95


def _intensity_range(x: np.ndarray, noise: float | None = None) -> tuple[float, float]:
    """The levels :func:`normalized_intensity` maps to 0 and 1; ``noise``:
    the standard deviation of the noise of ``x``'s pixels, when they hide it
    (a magnified view's, interpolated)."""
    sample = _subsample(x)
    lo, hi = np.percentile(sample, [1.0, 99.0])
    # Clipped at their rims, the few objects of a sparse field became flat
    # plateaus whose mid-level lay on the blur's foot: the contours of
    # 3.5-5 px spots ended 0.4-0.8 px outside them.
    middle, reach = float(np.median(sample)), SPARSE_TAIL * (_noise_sigma(x) if noise is None else noise)
    if reach > 0:
        hi = max(hi, middle + _beyond_the_clip(sample[sample > middle + reach] - middle, hi - middle, reach))
        lo = min(lo, middle - _beyond_the_clip(middle - sample[sample < middle - reach], middle - lo, reach))
    if hi <= lo:
        # Fewer than 1 % of pixels differ (a small spot): fall back to the
        # full range rather than flatten the picture.
        lo, hi = x.min(), x.max()
    return float(lo), float(hi)


def _beyond_the_clip(beyond: np.ndarray, clip: float, reach: float) -> float:
    """How far the objects of a sparse field lie from the median (``beyond``:
    the distances of the pixels more than ``reach`` from it), when the clip
    (at ``clip`` from it) cuts through most of them; else 0 (see
    SPARSE_TAIL)."""
    if beyond.size < SPARSE_LEAST:
        return 0.0
    typical = float(np.median(beyond))
    if typical <= clip or typical < 2.0 * reach:
        return 0.0
    return float(np.quantile(beyond, SPARSE_QUANTILE))


def _normalize(x: np.ndarray, out: np.ndarray | None = None, levels: tuple[float, float] | None = None) -> np.ndarray:
    """:func:`normalized_intensity` of a validated image, or ``x`` mapped
    from the ``levels`` of another (a larger view of the same image)."""
    lo, hi = _intensity_range(x) if levels is None else levels
    if out is None:
        out = np.empty(x.shape, dtype=np.float64)
    if hi <= lo:
        out.fill(0.0)
        return out
    np.subtract(x, lo, out=out)
    out *= 1.0 / (hi - lo)
    return np.clip(out, 0.0, 1.0, out=out)


def normalized_intensity(image) -> np.ndarray:
    """Robust min-max normalisation to [0, 1].

    ``clip((image - p1) / (p99 - p1), 0, 1)`` with ``p1`` and ``p99`` the
    1st and 99th percentiles, so a few hot or dead pixels do not set the
    scale, and 8-bit, 16-bit and float versions of one picture give the same
    result. In a sparse field (a few spots over 2 % of the image or less)
    the 99th (1st) percentile lies on the spots' rims: when most pixels
    beyond ``SPARSE_TAIL`` (4) noise standard deviations of the median lie
    beyond it, at least twice that far, the range reaches their
    ``SPARSE_QUANTILE`` (0.95), so that the spots are not clipped flat. For speed the
    percentiles of images over 16384 pixels are taken on a regular sub-grid
    of about that many pixels. If the percentiles coincide (fewer than ~1 %
    of the pixels differ, in a noiseless image) the min and max are used
    instead; a constant image gives all zeros.

    Parameters
    ----------
    image : (M, N) array_like
        Real 2D image.

    Returns
    -------
    normalized : (M, N) ndarray of float64 in [0, 1]
    """
    return _normalize(_as_image(image))


# --------------------------------------------------------------------------
# all features


@dataclass(frozen=True, eq=False)
class FeatureImages:
    """The feature images of one 2D picture (all float64, read-only, same shape).

    :func:`compute_features` returns the four arrays as views of a single
    ``(4, M, N)`` block, so they are kept or released together.

    Attributes
    ----------
    edges : ndarray
        Shen–Castan edge map, exactly 0 or 1.
    distance : ndarray
        Chamfer distance to the nearest edge pixel (pixels); the image
        diagonal everywhere if there is no edge.
    intensity : ndarray
        ``smoothed`` re-normalised to [0, 1] (:func:`normalized_intensity`):
        a noise-reduced intensity with full contrast.
    smoothed : ndarray
        ISEF-smoothed normalised image, in [0, 1] (in the normalised image's
        units, so its contrast is reduced near small objects).
    """

    edges: np.ndarray
    distance: np.ndarray
    intensity: np.ndarray
    smoothed: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """The images' ``(rows, cols)``."""
        return self.edges.shape

    @property
    def has_edges(self) -> bool:
        """Whether any edge was found (a constant image has none)."""
        return bool(self.edges.any())


def compute_features(
    image, *, b=0.9, window=7, high_quantile=0.95, low_ratio=0.5, min_length=8
) -> FeatureImages:
    """Compute the edge, distance and intensity images of a 2D grey image.

    The image is normalised (:func:`normalized_intensity`) and smoothed once
    (:func:`isef_smooth`); edges are found on the normalised image
    (:func:`shen_castan_edges`, same parameters) and their chamfer distance
    taken (:func:`chamfer_distance`).

    Parameters
    ----------
    image : (M, N) array_like
        Real 2D grey image, at least 3x3, any real dtype (bool is cast).
    b, window, high_quantile, low_ratio, min_length
        See :func:`shen_castan_edges`.

    Returns
    -------
    FeatureImages

    Raises
    ------
    ValueError
        With a hint at the fix if the image is RGB(A), a 3D stack, not 2D,
        empty, smaller than 3x3, complex or non-numeric, or holds NaN or
        infinite pixels; or if a parameter is out of range. A constant image
        is accepted: it has no edges.
    """
    b = _check_b(b)
    window = _check_window(window)
    high_quantile = _check_fraction(high_quantile, "high_quantile")
    low_ratio = _check_fraction(low_ratio, "low_ratio")
    min_length = _check_min_length(min_length)
    arr = _check_image(image, min_size=3)

    # One block holds every whole-image float array: the four outputs, and
    # before they are written the cast image, the normalised image / edge
    # strengths and a scratch array. Fresh pages are the largest cost of
    # this function on some systems (a 2 MiB array faulted in page by page
    # costs more than the arithmetic on it); numpy asks for huge pages for
    # blocks from 4 MiB.
    out = np.empty((4,) + arr.shape)
    edges_out, distance_out, intensity_out, smoothed_out = out
    if arr.dtype == np.float64:
        img = arr
    else:
        img = intensity_out
        np.copyto(img, arr, casting="unsafe")
    norm = _normalize(img, out=edges_out)
    smoothed = _isef(norm, b, out=smoothed_out)
    # norm is not returned: its buffer holds the edge strengths.
    edges, _ = _shen_castan(
        norm, smoothed, b, window, high_quantile, low_ratio, min_length,
        overwrite=True, work=distance_out,
    )
    # The ISEF is a weighted mean, so only round-off can leave [0, 1].
    np.clip(smoothed, 0.0, 1.0, out=smoothed)
    np.copyto(edges_out, edges)
    _chamfer(edges, out=distance_out)
    _normalize(smoothed, out=intensity_out)
    for arr in (out, edges_out, distance_out, intensity_out, smoothed_out):
        arr.flags.writeable = False  # views made earlier keep their own flag
    return FeatureImages(
        edges=edges_out, distance=distance_out, intensity=intensity_out, smoothed=smoothed_out
    )

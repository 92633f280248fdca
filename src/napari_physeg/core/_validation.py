"""One validation of the contours given to :func:`~.segmentation.segment`,
:func:`~.matching.match` and :func:`~.simulation.simulate`, and of their
numeric options.

A contour is an ``(N, 2)`` array of ``(row, col)`` nodes, closed implicitly,
each node given once. Nothing is dropped silently: results are indexed by the
caller's nodes (matching pairs, simulation frames), so a repeated node is an
error that says which nodes repeat, in every function alike.

The tests are centred and relative to the contour's own size, so they do not
depend on where the contour lies (``a + 1e10`` is the same contour as ``a``)
or on its scale.
"""

from __future__ import annotations

import inspect
from functools import lru_cache

import numpy as np
from scipy.spatial import ConvexHull, cKDTree

__all__ = ["check_contour", "check_drawing", "check_count", "check_number", "node_array", "on_one_line",
           "NEAR_DUPLICATE", "signature_of", "with_defaults"]

#: Two nodes closer than this fraction of the mean node spacing count as one
#: repeated node: the element's interpolation matrix becomes numerically
#: singular (measured: a node 1e-9 spacings from its neighbour made the
#: simulation diverge, 1e-6 did not).
NEAR_DUPLICATE = 1e-5
#: Smallest ratio of the second to the first singular value of the centred
#: nodes: below it they lie on one line (a triangle a millionth as high as
#: long reached the matching, whose element then failed on its spacing).
_COLLINEAR = 1e-6


def node_array(points, name: str = "contour", *, min_nodes: int = 3) -> np.ndarray:
    """``points`` as a float64 ``(N, 2)`` copy; ValueError if it cannot be
    one: empty, another shape, NaN or infinite values."""
    try:
        raw = np.asarray(points)
        kind = raw.dtype.kind
        # numpy drops an imaginary part with a warning only, and reads "12" and True as numbers.
        arr = None if kind in "cbUS" else np.array(raw, dtype=np.float64)
    except (TypeError, ValueError) as err:  # ragged, or objects that are no numbers
        raise ValueError(f"{name} must be an (N, 2) array of (row, col) nodes: {err}") from None
    if kind == "c":
        raise ValueError(f"{name} has complex coordinates: pass (row, col) as two real columns")
    if arr is None:
        raise ValueError(f"{name} holds {'True/False values' if kind == 'b' else 'text'}, not coordinates: pass "
                         "(row, col) numbers (e.g. read a CSV with napari_physeg.io.read_shapes_csv or np.loadtxt)")
    if arr.size == 0:
        raise ValueError(f"{name} is empty: draw a contour with at least {min_nodes} nodes")
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"{name} must be an (N, 2) array of (row, col) nodes, got shape {arr.shape}"
            + ("; for nD layers pass only the last two coordinates" if arr.ndim == 2 else "")
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    return arr


def check_contour(points, name: str = "contour", *, min_nodes: int = 3) -> np.ndarray:
    """Validate ``points`` as a closed contour; return it as float64 ``(N, 2)``.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        ``(row, col)`` nodes, the last joined to the first (not repeated).
    name : str, optional
        The argument's name, used in error messages.
    min_nodes : int, optional
        The fewest nodes accepted.

    Returns
    -------
    ndarray, shape (N, 2)
        The nodes as given (a contiguous float64 copy), none dropped.

    Raises
    ------
    ValueError
        If the array is empty or not ``(N, 2)``, holds NaN or infinite values,
        has fewer than ``min_nodes`` distinct nodes, repeats a node (exactly,
        or within :data:`NEAR_DUPLICATE` of the mean node spacing; the
        message names them), or has all its nodes on one line. A contour that
        crosses itself (a figure-8) is accepted.
    """
    arr = node_array(points, name, min_nodes=min_nodes)
    # Centred: the tests below then see the shape, not where it lies.
    centred = arr - arr.mean(axis=0)
    if len(arr) < min_nodes:
        _check_distinct(arr, name, min_nodes)
    # On one line first: a line drawn there and back, its nodes spaced along
    # it, repeats nodes too, and was told to pass each node once.
    if on_one_line(centred):
        _check_distinct(arr, name, min_nodes)  # (too few distinct nodes says more)
        raise ValueError(f"{name} is degenerate: its nodes lie on one line (or within a millionth of its length "
                         "of one) and enclose no area")
    try:
        _check_repeats(centred, name)
    except ValueError:
        # Too few distinct nodes says more than which of them repeat (counted
        # only then: np.unique took a third of a valid contour's check).
        _check_distinct(arr, name, min_nodes)
        raise
    return np.ascontiguousarray(arr)


#: A drawing whose nodes enclose, counted with their signs, less than this
#: share of the area of their convex hull goes back and forth over it, not
#: along one outline: a mask's pixels in raster order (np.argwhere) enclose
#: none, and took 50 s to be read as a drawing that crosses itself; a
#: bow-tie's two loops cancel. Of the 5,723 drawings of the benchmarks and
#: of the outside testers' runs the least held half its hull; a star with
#: spikes four times its core, a quarter.
IN_ORDER_SHARE = 0.05


#: A drawing of one point (a click: a Points layer's one point, or its
#: copies) is a circle of this radius about it, the click-sized circle of a
#: few pixels the user guide asks for (refused as too few nodes, it said
#: nothing of what to do instead).
CLICK_RADIUS = 3.0


def _pairs(points) -> np.ndarray | None:
    """``points`` as a numeric (N, 2) array, or None if they are not one
    (check_contour then says what is wrong: ragged, 3D, text...)."""
    try:
        arr = np.asarray(points)
    except (TypeError, ValueError):
        return None
    return arr if arr.dtype.kind in "iuf" and arr.ndim == 2 and arr.shape[1] == 2 else None


def clicked(points):
    """A circle of CLICK_RADIUS px about the one point of ``points``, if
    they are one point given once or more; else ``points`` as given."""
    arr = _pairs(points)
    if arr is None or not len(arr) or not np.all(np.isfinite(arr)) or np.ptp(arr, axis=0).any():
        return points
    angles = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    return arr[0].astype(float) + CLICK_RADIUS * np.column_stack([np.sin(angles), np.cos(angles)])


def once_each(points):
    """``points`` with every node that the next repeats exactly (the last,
    if the first repeats it) left out, if they are a numeric (N, 2) array;
    else as given. A closed ring as ``skimage.measure.find_contours``, QuPath
    and shapely write it repeats its first node at its end, and a mouse that
    paused repeats one in a row: neither says more than the nodes once."""
    arr = _pairs(points)
    if arr is None or len(arr) < 2:
        return points
    repeats = np.all(arr == np.roll(arr, -1, axis=0), axis=1)  # (the last, where it repeats the first)
    return arr[~repeats] if repeats.any() and not repeats.all() else points


def check_drawing(points, name: str = "init") -> np.ndarray:
    """:func:`check_contour` for a drawing that stands for an object's
    outline (segment's and track's): also a ValueError when its nodes do not
    follow one outline in order (see IN_ORDER_SHARE). One point is a click
    (see :func:`clicked`); a node repeated in a row, or the first at the end,
    is taken once (see :func:`once_each`: the contour is resampled anyway)."""
    from .contour import signed_area  # (contour imports this module)

    arr = check_contour(once_each(clicked(points)), name)
    area = abs(signed_area(arr))
    if area >= IN_ORDER_SHARE * float(np.prod(np.ptp(arr, axis=0))):  # most: the hull is no larger than the box
        return arr
    hull = ConvexHull(arr - arr.mean(axis=0)).volume
    if area < IN_ORDER_SHARE * hull:
        raise ValueError(
            f"{name} goes back and forth: its {len(arr)} nodes enclose {area:.3g} px² of the {hull:.3g} px² they "
            "span, so they do not follow one outline in order (a figure-8 whose two loops cancel, or a mask's "
            "pixels as np.argwhere lists them); draw one outline around the object, or pass a mask's outline in "
            "order, e.g. skimage.measure.find_contours(mask, 0.5)[0]")
    return arr


def on_one_line(points: np.ndarray) -> bool:
    """Whether ``points`` lie on one line, or one point (to :data:`_COLLINEAR`
    of their extent): they enclose no area."""
    singular = np.linalg.svd(np.asarray(points, float) - np.mean(points, axis=0), compute_uv=False)
    return bool(singular[1] <= _COLLINEAR * singular[0])


def _check_distinct(arr: np.ndarray, name: str, min_nodes: int) -> None:
    distinct = len(np.unique(arr, axis=0))
    if distinct < min_nodes:
        raise ValueError(
            f"{name} has {distinct} distinct node(s); at least {min_nodes} are needed for a closed contour"
        ) from None


def _check_repeats(centred: np.ndarray, name: str) -> None:
    """Raise when two nodes coincide (or nearly), naming them."""
    n = len(centred)
    if np.array_equal(centred[0], centred[-1]):
        raise ValueError(
            f"{name} repeats its first node at the end (node {n - 1}): a contour is closed implicitly, "
            f"pass each node once (e.g. {name}[:-1])"
        )
    edges = np.diff(centred, axis=0, append=centred[:1])
    spacing = float(np.hypot(edges[:, 0], edges[:, 1]).mean())
    pairs = cKDTree(centred).query_pairs(NEAR_DUPLICATE * spacing, output_type="ndarray")
    if len(pairs):
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        shown = ", ".join(f"{i} and {j}" for i, j in pairs[:5]) + (" ..." if len(pairs) > 5 else "")
        consecutive = np.any((pairs[:, 1] - pairs[:, 0] == 1) | (pairs[:, 1] - pairs[:, 0] == n - 1))
        kind = "repeated consecutive nodes" if consecutive else f"{len(pairs)} identical node(s)"
        # Nodes apart along the contour that meet: it passes twice through one
        # point (a figure-8 drawn in napari, its nodes spaced along it, meets
        # itself where it crosses).
        fix = "pass each node once" if consecutive else \
            "pass each node once, and draw a contour that does not cross or touch itself"
        raise ValueError(
            f"{name} has {kind} (nodes {shown} coincide, within {NEAR_DUPLICATE:g} of the node spacing); {fix}"
        )


def check_number(value, name: str, *, minimum: float = 0.0, inclusive: bool = True,
                 maximum: float = np.inf) -> float:
    """``value`` as a float, or a ValueError naming ``name``: a finite number
    (numpy's too; not a flag or a text) at least ``minimum`` (above it when
    not ``inclusive``) and at most ``maximum``."""
    try:
        number = np.nan if isinstance(value, (bool, np.bool_, str, bytes)) else float(value)
    except (TypeError, ValueError):
        number = np.nan
    low_ok = number >= minimum if inclusive else number > minimum
    if not (np.isfinite(number) and low_ok and number <= maximum):
        bound = f"{'at least' if inclusive else 'above'} {minimum:g}"
        if np.isfinite(maximum):
            bound += f" and at most {maximum:g}"
        raise ValueError(f"{name} must be a number {bound}, got {value!r}")
    return number


def check_callback(callback) -> None:
    """ValueError unless ``callback`` is None or callable: refused before any
    work, not at the first progress (after the first object of a movie)."""
    if callback is not None and not callable(callback):
        raise ValueError(f"callback must be callable or None, got {callback!r}")


def check_count(value, name: str, minimum: int, *, allow_none: bool = False) -> int | None:
    """``value`` as an int, or a ValueError naming ``name``: an integer
    (numpy's too; not a flag, nor a float that would be cut) of at least
    ``minimum``, or None when ``allow_none``."""
    if value is None and allow_none:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        tail = " or None" if allow_none else ""
        raise ValueError(f"{name} must be an integer >= {minimum}{tail}, got {value!r}")
    return int(value)


@lru_cache(maxsize=None)
def signature_of(function) -> inspect.Signature:
    """``inspect.signature(function)``, read once: it takes 0.3 ms, and a
    tracked object asks for :func:`~.segmentation.segment`'s and
    :func:`~.matching.match`'s on every frame."""
    return inspect.signature(function)


def with_defaults(function, args: tuple, options: dict) -> dict:
    """``function``'s arguments, by name, for ``args`` and the keyword
    ``options``, with its defaults filled in (a misspelt option: TypeError)."""
    bound = signature_of(function).bind(*args, **options)
    bound.apply_defaults()
    return dict(bound.arguments)

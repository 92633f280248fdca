"""Segmentation with a physical deformable contour (paper sections 2 and 4.1).

:func:`segment` turns a rough initial contour into an elastic body (Sclaroff's
element made of a virtual material) and lets image forces drive it, by the
dynamic equilibrium equation ``M U'' + C U' + K U = F``, onto the border of
the object it surrounds or lies inside.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial import cKDTree

from .contour import as_contour, cut_pinches, outward_normals, perimeter, remove_loops, resample, segment_lengths, signed_area
from .dynamics import DivergenceError, ModalIntegrator, NewmarkIntegrator
from .element import coefficient_system, rayleigh_coefficients, reference_frequency_range
from .features import chamfer_distance, compute_features, normalized_intensity
from .forces import FORCE_NAMES, ForceField, normalize_weights
from .materials import Material, get_material
from .region import _disk, drawing_levels, object_region, objectness
from .subpixel import polish

__all__ = ["segment", "SegmentationResult", "region_features"]

#: Nodes are redistributed (and the element rebuilt) when an edge of the
#: contour grows or shrinks by this factor relative to the target spacing.
REMESH_STRETCH = 2.0


@dataclass(frozen=True)
class SegmentationResult:
    """What :func:`segment` returns.

    Attributes
    ----------
    contour : ndarray, shape (M, 2)
        Final nodes ``(row, col)``.
    steps : int
        Time steps taken.
    converged : bool
        True when the contour came to rest on the object's border (see
        ``stop_reason``).
    stop_reason : str
        ``"converged"`` (at rest, at least 70 % of the nodes on an edge or an
        object/background switch), ``"stalled"`` (at rest elsewhere: nothing
        in reach pulls it), ``"max_steps"`` or ``"cancelled"``. At rest means
        no node moved more than ``tol`` for ``patience`` steps, or the area and
        centroid changed by less than 0.1 px over 50 steps.
    history : tuple of ndarray
        Sub-sampled evolution, first the resampled initial contour, last the
        final one.
    polarity : int
        +1 when the object was taken as brighter than its background, -1 darker.
    timings : dict
        Seconds spent on ``"features"``, ``"model"`` (element assembly and
        factorisation), ``"evolution"`` and ``"total"``.
    """

    contour: np.ndarray
    steps: int
    converged: bool
    stop_reason: str
    history: tuple
    polarity: int
    timings: dict = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return len(self.contour)


def _validate_image(image) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[-1] in (3, 4):
        raise ValueError(
            f"image has shape {arr.shape}: it looks like an RGB(A) image. Pass one channel "
            "(e.g. image[..., 1]) or convert it to grey (skimage.color.rgb2gray)"
        )
    if arr.ndim != 2:
        raise ValueError(
            f"image must be a 2D array, got shape {arr.shape}; for a stack or volume pass the 2D "
            "slice to segment (e.g. image[z])"
        )
    return arr


def _clip_to_image(init: np.ndarray, shape) -> np.ndarray:
    hi = np.array(shape, dtype=float) - 1.0
    outside = np.any((init < 0) | (init > hi), axis=1)
    if outside.all():
        lo_box, hi_box = init.min(0), init.max(0)
        if np.any(hi_box < 0) or np.any(lo_box > hi):
            raise ValueError(
                f"init lies wholly outside the image (image shape {tuple(shape)}, contour spans rows "
                f"{lo_box[0]:.1f}..{hi_box[0]:.1f}, cols {lo_box[1]:.1f}..{hi_box[1]:.1f}); "
                "check that the contour and image use the same coordinates"
            )
    if outside.any():
        warnings.warn(
            f"{outside.sum()} of {len(init)} nodes of init lie outside the image and were clipped to it",
            UserWarning,
            stacklevel=3,
        )
        init = as_contour(np.clip(init, 0.0, hi), name="init (clipped to the image)")
    return init


#: The feature images are computed on a window around the contour when it
#: covers at most this fraction of the image (below it the saving beats the
#: cost of the rare re-computation when the contour grows out of its window).
WINDOW_MAX_FRACTION = 0.5


def _window(contour: np.ndarray, shape, margin: float, keep=None) -> tuple[slice, slice]:
    """Rows and columns of the image within ``margin`` px of ``contour``'s
    bounding box (and covering the window ``keep``, if given)."""
    lo = np.maximum(np.floor(contour.min(0) - margin), 0).astype(int)
    hi = np.minimum(np.ceil(contour.max(0) + margin) + 1, shape).astype(int)
    if keep is not None:
        lo = np.minimum(lo, [keep[0].start, keep[1].start])
        hi = np.maximum(hi, [keep[0].stop, keep[1].stop])
    return slice(int(lo[0]), int(hi[0])), slice(int(lo[1]), int(hi[1]))


def _near_window_border(nodes: np.ndarray, window, shape, guard: float) -> bool:
    """True when a node of ``nodes`` (window coordinates) is within ``guard`` px
    of a side of the window that is not a side of the image."""
    rows, cols = window
    h, w = rows.stop - rows.start, cols.stop - cols.start
    lo, hi = nodes.min(0), nodes.max(0)
    return bool((rows.start > 0 and lo[0] < guard) or (cols.start > 0 and lo[1] < guard)
                or (rows.stop < shape[0] and hi[0] > h - 1 - guard)
                or (cols.stop < shape[1] and hi[1] > w - 1 - guard))


#: Edges count only within this many neck widths (see region.object_region)
#: of the object's own region: texture inside it and neighbours' far sides
#: do not hold the contour.
EDGE_GATE = 3.0


def region_features(intensity, feats, drawing, polarity=None):
    """Object-ness and edge images for the object the user drew.

    Parameters
    ----------
    intensity : (H, W) ndarray
        Lightly smoothed, normalised intensity.
    feats : FeatureImages
        Edge and distance images of the same window.
    drawing : (N, 2) ndarray
        The initial contour in the window's frame.
    polarity : {None, 1, -1}
        Known polarity, or None to infer it from the drawing.

    Returns
    -------
    signed, edges : ndarray
        Object-ness in [-1, 1] (+1 on the object's own region, -1 on its
        background and on look-alike neighbours), and the edge map gated to a
        band around that region.
    polarity : int
    """
    model = drawing_levels(intensity, drawing, polarity)
    if not model.is_visible(intensity):
        # No object here that the eye could tell from its background: no
        # region force (edges may still guide the contour).
        return np.zeros(intensity.shape, np.float32), feats.edges, model.polarity
    signed = objectness(intensity, model)
    region = object_region(signed, drawing, model)
    if region is None:
        return signed, feats.edges, model.polarity
    signed = np.where(region, np.where(signed > 0, signed, 1.0), np.where(signed > 0, -1.0, signed))
    # Texture inside the object's own region is the object: no edge holds
    # the contour there, and only a rim keeps graded object-ness values (for
    # the sub-pixel balance of the region force). Outside, edges count within
    # a band around the region (neighbours' far sides do not).
    size = np.sqrt(max(region.sum(), 1) / np.pi)
    rim = int(np.clip(round(0.1 * size), 1, 3))
    gate = int(np.ceil(EDGE_GATE * rim))
    r8 = region.view(np.uint8)
    interior = cv2.erode(r8, _disk(rim + 1)).view(bool)
    band = cv2.dilate(r8, _disk(gate)).view(bool) & ~interior
    edges = np.where(band, feats.edges, 0.0)
    signed[cv2.erode(r8, _disk(rim)).view(bool)] = 1.0
    return signed.astype(np.float32), edges, model.polarity


def _update_caps(move, normals, cap, last_sign, max_step_length, tol):
    """Per-node trust region (as in Rprop): a node whose motion along its
    normal reverses (it stepped over its equilibrium) halves its cap, one that
    keeps going lets it grow back; so every material comes to rest."""
    sign = np.sign((move * normals).sum(1))
    cap = np.where(sign * last_sign < 0, 0.5 * cap, np.minimum(1.25 * cap, max_step_length))
    return np.maximum(cap, 0.25 * tol), sign


def _total_step(sim, system, f, nodes, rest, cap):
    """One step with the initial shape as rest shape (full dynamics, state kept).

    Forces on nodes that would move more than their cap are scaled down
    before the step is taken, so the integrator's state stays consistent.
    """
    m = len(nodes)
    for _ in range(2):
        U = system.G @ sim.trial(system.G @ f)
        move = np.column_stack([U[:m], U[m:]]) + rest - nodes
        reach = np.linalg.norm(move, axis=1)
        over = reach > cap
        if not over.any():
            break
        scale = np.where(over, cap / np.maximum(reach, 1e-12), 1.0)
        f = f * np.concatenate([scale, scale])
    U = system.G @ sim.step(system.G @ f)
    return np.column_stack([U[:m], U[m:]]) + rest - nodes


#: Non-neighbouring nodes closer than this many node spacings pinch the
#: contour: it is split there (see contour.cut_pinches).
PINCH_GAP = 0.35

#: A contour whose area and centroid changed by less than this (in px of
#: mean normal displacement) over PLATEAU_STEPS steps has come to rest, even
#: if a few nodes still jitter.
PLATEAU_MOTION = 0.1
PLATEAU_STEPS = 50

#: At rest, the contour is on the object when at least this fraction of its
#: nodes rest on a feature (an edge or an object/background switch).
ON_BORDER_FRACTION = 0.7


def _distance_with_image_border(edges: np.ndarray, window, shape) -> np.ndarray:
    """Chamfer distance to the nearest edge, the image's own border counting
    as an edge: an object cut by the border ends there, and a node on the
    border does not reach across the object for the far side's edge."""
    rows, cols = window
    pad = ((int(rows.start == 0), int(rows.stop == shape[0])), (int(cols.start == 0), int(cols.stop == shape[1])))
    framed = np.pad(np.asarray(edges) > 0, pad, constant_values=True)
    distance = chamfer_distance(framed)
    return distance[pad[0][0]: distance.shape[0] - pad[0][1], pad[1][0]: distance.shape[1] - pad[1][1]]


def _element(nodes, sigma, material, rayleigh, integrator, dt, divergence_limit):
    """Sclaroff's element for ``nodes`` and its time integrator."""
    system = coefficient_system(nodes, sigma, material)
    mu, gamma = rayleigh
    if integrator == "newmark":
        sim = NewmarkIntegrator(system.M, system.K, mu * system.M + gamma * system.K, dt=dt,
                                divergence_limit=divergence_limit)
    else:
        sim = ModalIntegrator(system.M, system.K, mu=mu, gamma=gamma, dt=dt, divergence_limit=divergence_limit)
    return system, sim


def _needs_remesh(nodes: np.ndarray, spacing: float) -> bool:
    seg = segment_lengths(nodes)
    return bool(seg.max() > REMESH_STRETCH * spacing or seg.min() < spacing / REMESH_STRETCH
                or len(cKDTree(nodes).query_pairs(PINCH_GAP * spacing)) > 0)


class _Plateau:
    """Detects a contour whose shape no longer changes over many steps."""

    def __init__(self):
        self.trace = []

    def reached(self, nodes: np.ndarray) -> bool:
        area = signed_area(nodes)
        length = max(perimeter(nodes), 1e-9)
        self.trace.append((area / length, *nodes.mean(0)))
        if len(self.trace) <= PLATEAU_STEPS:
            return False
        then = np.array(self.trace[-PLATEAU_STEPS - 1])
        now = np.array(self.trace[-1])
        return bool(np.abs(now - then).max() < PLATEAU_MOTION)


def _rest_reason(field: ForceField, nodes: np.ndarray) -> str:
    """Why a contour at rest stopped: on the object's border, or not."""
    return "stalled" if field.on_border(nodes).mean() < ON_BORDER_FRACTION else "converged"


def _divergence(steps: int, stiffness: float) -> DivergenceError:
    return DivergenceError(
        f"the contour's element became numerically singular at step {steps} and could not be repaired; "
        f"try a finer node spacing (n_nodes) or a smaller sigma_factor (stiffness r = {stiffness:g})"
    )


def segment(
    image,
    init,
    *,
    material: str | Material = "rubber",
    stiffness: float = 2000.0,
    n_nodes: int | None = None,
    sigma: float | None = None,
    sigma_factor: float = 1.0,
    forces=FORCE_NAMES,
    weights: dict | None = None,
    polarity: str = "auto",
    damping_ratio: float = 1.0,
    dt: float = 1.0,
    reference: str = "incremental",
    integrator: str = "newmark",
    max_steps: int = 1000,
    max_step_length: float = 2.0,
    tol: float = 0.02,
    patience: int = 5,
    max_line_length: float = 40.0,
    isef_b: float = 0.7,
    refine: bool = True,
    history_every: int = 5,
    callback=None,
) -> SegmentationResult:
    """Segment the object around (or inside) ``init`` with a physical contour.

    The initial contour is resampled to evenly spaced nodes and modelled as an
    elastic membrane of the chosen virtual material (Sclaroff's isoparametric
    element). External forces from the image (Shen-Castan edges, intensity and
    chamfer distance to the nearest edge, sampled along adaptive normal lines)
    drive it, by the dynamic equilibrium equation ``M U'' + C U' + K U = F``
    integrated with an unconditionally stable scheme, until it rests on the
    object's border.

    Parameters
    ----------
    image : (H, W) array_like
        Grey-level image of any real dtype. RGB images must be reduced to one
        channel first.
    init : (N, 2) array_like
        Initial contour, ``(row, col)`` nodes, closed without a repeated node,
        ``N >= 3``. Nodes outside the image are clipped to it (with a warning).
    material : str or Material, optional
        Virtual material: a preset of :data:`MATERIALS` (``"rubber"``,
        ``"copper"``, ...) or a :class:`Material`.
    stiffness : float, optional
        The paper's stiffness constant ``r`` (N/m): the image force on a node
        is ``r`` times its dimensionless feature force (at most the sum of the
        weights). Stiffer materials need larger ``r`` (rubber ~2e3, copper ~1e6).
    n_nodes : int, optional
        Nodes of the initial model (default: one every ~3 px, 24 to 1000). The
        spacing is then kept as the contour grows or shrinks.
    sigma : float, optional
        Gaussian width of the element (px). Default ``sigma_factor`` times the
        node spacing.
    sigma_factor : float, optional
        Node interaction relative to the spacing, typically 0.75-1.5.
    forces : sequence of str, optional
        Image forces to use, from ``("edges", "intensity", "distance")``.
    weights : dict, optional
        Weight of each force (defaults 0.4, 0.3, 0.3).
    polarity : {"auto", "bright", "dark"}, optional
        Whether the object is brighter or darker than its background; "auto"
        compares the inside of ``init`` with a band around it.
    damping_ratio : float, optional
        Rayleigh damping ratio at the lowest and highest natural frequencies.
    dt : float, optional
        Time step (s).
    reference : {"incremental", "total"}, optional
        "incremental" (default) takes the current shape as the rest shape after
        every step, so the contour keeps moving while image forces act and can
        change its node count; "total" keeps the initial shape as rest shape
        (elastic forces grow with the distance travelled).
    integrator : {"newmark", "modal"}, optional
        Newmark's trapezoidal rule, or mode superposition.
    max_steps : int, optional
        Upper bound on time steps.
    max_step_length : float, optional
        No node moves more than this (px) in one step: forces on faster nodes
        are scaled down, so the contour cannot jump over a 1-px edge.
    tol, patience : float, int, optional
        Converged when no node moves more than ``tol`` px per step for
        ``patience`` consecutive steps.
    max_line_length : float, optional
        Longest half-length of a normal line (px).
    isef_b : float, optional
        Smoothing of the Shen-Castan filter, in (0, 1).
    refine : bool, optional
        After coming to rest, let the region (intensity) force alone settle
        the nodes for sub-pixel accuracy (edge pixels lie up to half a pixel
        off the true border), then polish them onto the border measured on
        the raw image, averaged along the contour as the image noise requires,
        with the polygon's edges fitted to it
        (:func:`~napari_physeg.core.subpixel.polish`; no node moves more than
        1.5 px). Only with the incremental reference, the intensity force,
        and a contour that came to rest.
    history_every : int, optional
        Keep one contour in ``history`` every this many steps.
    callback : callable, optional
        ``callback(step, contour)`` after each step; return ``False`` to stop.

    Returns
    -------
    SegmentationResult

    Raises
    ------
    ValueError
        For bad input: a non-2D image, NaN pixels, a constant image, a contour
        with fewer than 3 distinct nodes or wholly outside the image, bad
        parameters; and when the contour collapses to a point because no
        object border lies within reach of it.
    DivergenceError
        If the element stays numerically singular after the contour was
        repaired (pinches, loops and crowded nodes cut, nodes resampled), or
        the integration produced non-finite or exploding displacements.

    Notes
    -----
    The feature images are computed on a window around the contour (its
    bounding box plus ``2 (max_line_length + 8)`` px) when that window covers
    at most half the image, and on a larger window whenever the contour comes
    within ``max_line_length + 8`` px of its border; so a small object in a
    large image costs about what it would cost in a small one.

    Examples
    --------
    >>> from napari_physeg import data
    >>> obj = data.ellipse()
    >>> res = segment(obj.image, obj.init_near)
    >>> res.converged
    True
    """
    t_start = time.perf_counter()
    image = _validate_image(image)
    init = as_contour(init, name="init")
    material = get_material(material)
    weights = normalize_weights(forces, weights)
    if not (np.isfinite(stiffness) and stiffness > 0):
        raise ValueError(f"stiffness r must be a positive number, got {stiffness!r}")
    if reference not in ("incremental", "total"):
        raise ValueError(f"reference must be 'incremental' or 'total', got {reference!r}")
    if integrator not in ("newmark", "modal"):
        raise ValueError(f"integrator must be 'newmark' or 'modal', got {integrator!r}")
    if polarity not in ("auto", "bright", "dark"):
        raise ValueError(f"polarity must be 'auto', 'bright' or 'dark', got {polarity!r}")
    if not (max_step_length > 0 and tol > 0 and int(max_steps) >= 0):
        raise ValueError("max_step_length and tol must be positive and max_steps non-negative")
    if n_nodes is not None and int(n_nodes) < 3:
        raise ValueError(f"n_nodes must be at least 3, got {n_nodes!r}")

    # The drawing as the user made it (partly beyond the image, maybe) tells
    # the object from its background; the clipped one starts the contour.
    drawing = init
    init = _clip_to_image(init, image.shape)
    # Feature images on a window around the contour: the forces read them
    # along normal lines of at most max_line_length px, so a guard band of
    # that width (and as much again as margin) suffices; the window grows
    # when the contour nears its border. On a large image with a small
    # object this is most of the cost of a segmentation.
    guard = float(max_line_length) + 8.0
    margin = 2.0 * guard
    whole_image = (slice(0, image.shape[0]), slice(0, image.shape[1]))
    window = _window(init, image.shape, margin)
    if (window[0].stop - window[0].start) * (window[1].stop - window[1].start) > WINDOW_MAX_FRACTION * image.size:
        window = whole_image
    pol = {"bright": 1, "dark": -1}.get(polarity)

    def fields_for(window):
        """Force fields (all forces, then the region alone) on ``window``."""
        nonlocal pol
        sub = image[window]
        origin = np.array([window[0].start, window[1].start], dtype=float)
        feats = compute_features(sub, b=isef_b)
        if not feats.edges.any() and np.ptp(feats.intensity) <= 1e-12:
            if sub.shape != image.shape:  # nothing here: look at the whole image
                return fields_for(whole_image)
            raise ValueError("image is constant: there is no object border to segment")
        # The region force needs the border where it is: a light denoising,
        # not the strong ISEF smoothing used for edge detection.
        intensity = cv2.GaussianBlur(normalized_intensity(sub), (0, 0), 1.0, borderType=cv2.BORDER_REFLECT)
        signed, edges, pol = region_features(intensity, feats, drawing - origin, pol)
        distance = _distance_with_image_border(edges, window, image.shape)
        field_ = ForceField.from_features(edges, distance, signed, weights, max_length=max_line_length)
        fields = [field_]
        if refine and reference == "incremental" and weights.get("intensity", 0) > 0 and len(weights) > 1:
            fields.append(field_.with_weights({"intensity": sum(weights.values())}))
        return window, origin, fields

    window, origin, fields = fields_for(window)
    t_features = time.perf_counter()

    length = perimeter(init)
    if n_nodes is None:
        n_nodes = int(np.clip(round(length / 3.0), 24, 1000))
    spacing = length / int(n_nodes)
    nodes = resample(init, int(n_nodes)) - origin
    sigma_used = float(sigma) if sigma is not None else sigma_factor * spacing
    if not (np.isfinite(sigma_used) and 0 < sigma_used <= 2.0 * spacing):
        raise ValueError(
            f"sigma = {sigma_used!r} must be positive and at most 2 x the node spacing ({spacing:.3g} px); "
            "typical values are 0.75-1.5 x the spacing"
        )
    divergence_limit = 10.0 * float(np.hypot(*image.shape))
    model_time = 0.0
    rayleigh = rayleigh_coefficients(damping_ratio, *reference_frequency_range(spacing, sigma_used, material))

    def build(nodes):
        nonlocal model_time
        t0 = time.perf_counter()
        try:
            system, sim = _element(nodes, sigma_used, material, rayleigh, integrator, dt, divergence_limit)
        finally:
            model_time += time.perf_counter() - t0
        return system, sim

    def repaired(nodes):
        """The contour without pinches, loops and crowded nodes, evenly resampled."""
        # Clipped first: nodes pushed past a corner of the image meet there.
        inside = np.clip(nodes, -0.5, bounds)
        fixed = resample(remove_loops(cut_pinches(inside, PINCH_GAP * spacing)), spacing=spacing)
        keep = np.linalg.norm(fixed - np.roll(fixed, 1, axis=0), axis=1) > 1e-3 * spacing
        return fixed[keep] if keep.sum() >= 3 else fixed

    bounds = np.array(image[window].shape, dtype=float) - 0.5  # pixel edges: the image's extent
    system, sim = build(nodes)
    rest = nodes.copy()
    history = [nodes + origin]
    cap = np.full(len(nodes), float(max_step_length))
    last_sign = np.zeros(len(nodes))
    quiet = 0
    stop_reason = "max_steps"
    steps = 0
    plateau = _Plateau()
    # Phase 1 uses every force; once at rest, a short second phase lets the
    # region force alone (sub-pixel: it balances where the lightly smoothed
    # intensity crosses the object/background mid-level) settle the nodes
    # that edge pixels hold half a pixel off the true border; a geometric
    # polish (subpixel.polish) then ends them on the border of the raw image.
    phase = 0
    for steps in range(1, int(max_steps) + 1):
        if _near_window_border(nodes, window, image.shape, guard):
            # The contour grew toward the window's border: a larger window.
            old_origin = origin
            window, origin, fields = fields_for(_window(nodes + origin, image.shape, margin, keep=window))
            shift = old_origin - origin
            nodes, rest = nodes + shift, rest + shift
            bounds = np.array(image[window].shape, dtype=float) - 0.5
        field_now = fields[phase]
        normals = outward_normals(nodes)
        F = stiffness * field_now(nodes, normals)
        f = np.concatenate([F[:, 0], F[:, 1]])
        m = len(nodes)
        try:
            if reference == "incremental":
                # The current shape is the rest shape and the body starts the
                # step at rest: one solve of the dynamic equation over dt.
                U = system.G @ sim.from_rest(system.G @ f)
                move = np.column_stack([U[:m], U[m:]])
                cap, last_sign = _update_caps(move, normals, cap, last_sign, max_step_length, tol)
                reach = np.linalg.norm(move, axis=1)
                move *= np.minimum(1.0, cap / np.maximum(reach, 1e-12))[:, None]
            else:
                U = system.G @ sim.trial(system.G @ f)
                proposal = np.column_stack([U[:m], U[m:]]) + rest - nodes
                cap, last_sign = _update_caps(proposal, normals, cap, last_sign, max_step_length, tol)
                move = _total_step(sim, system, f, nodes, rest, cap)
        except (DivergenceError, np.linalg.LinAlgError, RuntimeError, ValueError):
            # Image forces are bounded and the scheme unconditionally stable:
            # a blow-up means the element is ill-conditioned (nodes of two
            # parts of the contour nearly touching). Repair it and go on.
            if reference != "incremental":
                raise _divergence(steps, stiffness) from None
            nodes = repaired(nodes)
            try:
                system, sim = build(nodes)
            except (np.linalg.LinAlgError, RuntimeError, ValueError) as err2:
                raise _divergence(steps, stiffness) from err2
            cap, last_sign = np.full(len(nodes), float(max_step_length)), np.zeros(len(nodes))
            continue
        new_nodes = np.clip(nodes + move, -0.5, bounds)
        moved = float(np.abs(new_nodes - nodes).max())
        if not np.isfinite(moved) or moved > divergence_limit:
            raise _divergence(steps, stiffness)
        nodes = new_nodes
        if reference == "incremental" and _needs_remesh(nodes, spacing):
            old = nodes
            nodes = repaired(nodes)
            if len(nodes) < 3 or abs(signed_area(nodes)) < 1.0:
                break
            nearest = cKDTree(old).query(nodes)[1]
            cap, last_sign = cap[nearest], last_sign[nearest]
            try:
                system, sim = build(nodes)
            except (np.linalg.LinAlgError, RuntimeError, ValueError):
                raise _divergence(steps, stiffness) from None
        quiet = quiet + 1 if moved < tol else 0
        if steps % max(int(history_every), 1) == 0:
            history.append(nodes + origin)
        if callback is not None and callback(steps, nodes + origin) is False:
            stop_reason = "cancelled"
            break
        if quiet >= patience or plateau.reached(nodes):
            if phase == len(fields) - 1:
                stop_reason = _rest_reason(field_now, nodes)
                break
            phase += 1
            quiet = 0
            plateau = _Plateau()
            cap = np.full(len(nodes), 0.5 * float(max_step_length))
    if stop_reason != "cancelled" and (len(nodes) < 3 or abs(signed_area(nodes)) < 1.0):
        # Nothing held it: the region force shrinks a contour drawn on a
        # uniform background until it is a point. Say so rather than return it.
        raise ValueError(
            f"the contour collapsed to a point after {steps} steps: no object border was found within reach "
            f"({max_line_length:g} px) of the initial contour; draw it around the object, closer to its border"
        )
    if stop_reason == "converged" and refine and reference == "incremental" and weights.get("intensity", 0) > 0:
        # At rest every node is within a few tenths of a pixel of the border,
        # read on smoothed images and each on its own noise: measure the border
        # on the raw image and fit the polygon to it (see subpixel.polish).
        nodes = np.clip(polish(image[window], nodes, polarity=pol), -0.5, bounds)
    nodes = nodes + origin
    if not np.array_equal(history[-1], nodes):
        history.append(nodes.copy())
    t_end = time.perf_counter()
    return SegmentationResult(
        contour=nodes,
        steps=steps,
        converged=stop_reason == "converged",
        stop_reason=stop_reason,
        history=tuple(history),
        polarity=pol,
        timings={
            "features": t_features - t_start,
            "model": model_time,
            "evolution": t_end - t_features - model_time,
            "total": t_end - t_start,
        },
    )

"""Simulation of the deformation of one contour into another (paper section 4.2).

The initial contour ``a`` is an elastic body (Sclaroff's element of a virtual
material). Each node is pulled toward a target on ``b`` by a force
proportional to its distance from it:

* a matched node ``i`` toward its partner, ``F_i = q (X_T,i - X_J,i)`` (eq. 17);
* an unmatched node ``b`` lying between the matched nodes ``a`` and ``c``
  toward the target nodes ``p`` lying between their partners ``a'`` and ``c'``,
  ``F_b = q sum_p W_p (X_T,p - X_J,b)`` (eq. 18), with weights that decrease
  with the affinity ``Z_bp`` (eq. 12) and sum to 1, so that eq. 18 is a spring
  toward the weighted target ``sum_p W_p X_T,p``; when no node lies between
  ``a'`` and ``c'``, ``a'`` and ``c'`` themselves are used.

Both forces are linear in the current shape ``X_J``, so they are treated
implicitly: ``q S`` joins the stiffness in the factored matrix, which makes the
integration stable for any ``q``. The dynamic equation ``M U'' + C U' + K U =
F`` is integrated with Newmark's method with ``a`` as the rest shape, so the
contour comes to rest where the targets' pull balances the elastic force of its
deformation: on ``b`` for a soft material or a strong ``q`` (rubber with the
paper's ``q = 30000 N/m``), short of it for a stiff one (copper). The frames
are taken at even intervals of the path travelled.

A rigid move costs a body no elastic energy, but the element has no
rigid-body zero modes (``docs/physics.md`` section 4): moved or turned as a
whole it resists as if bent. So the rigid part of the move (the rotation and
shift that bring ``a`` closest to its targets) is taken out first: the
element deforms toward the targets as seen from a frame that follows that
rigid move, which carries it along as a free body held by the springs would
move (see :class:`_RigidCarry`). A contour simulated into a shifted or
turned copy of itself then ends on it, its frames turned and moved copies.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ._drain import drain
from ._validation import check_callback, check_contour, check_count, check_number, with_defaults
from .contour import rotation_between, rotation_matrix, segment_lengths, warn_if_figure_eight
from .dynamics import DivergenceError, ModalIntegrator, NewmarkIntegrator
from .element import (
    coefficient_system,
    default_sigma,
    natural_frequency_range,
    rayleigh_coefficients,
    reference_frequency_range,
)
from .materials import Material, get_material

__all__ = ["simulate", "iter_simulate", "SimulationResult", "SimulationProgress", "node_targets"]

#: Up to this many nodes the simulation uses exact mode superposition (dense
#: eigenproblem); above it, Newmark's method on the sparse system.
DENSE_NODES = 300


@dataclass(frozen=True)
class SimulationResult:
    """What :func:`simulate` returns.

    Attributes
    ----------
    frames : ndarray, shape (T, Na, 2)
        Shapes at even intervals of the path: ``frames[0]`` is ``a``, the last
        rests on ``b``.
    targets : ndarray, shape (Na, 2)
        The point of ``b`` each node of ``a`` is pulled toward (its partner, or
        eq. 18's weighted target for an unmatched node).
    times : ndarray, shape (T,)
        Simulated time (s) of each frame.
    steps : int
        Time steps taken.
    converged : bool
        True when the contour came to rest (within ``tol`` of its equilibrium).
    stop_reason : str
        ``"converged"`` (came to rest), ``"max_steps"`` (still moving after
        ``max_steps``) or ``"cancelled"`` (the frames then end where it was
        stopped).
    rest : ndarray, shape (Na, 2)
        The equilibrium shape (where the contour comes to rest).
    timings : dict
        Seconds spent on ``"model"``, ``"evolution"`` and ``"total"``.
    """

    frames: np.ndarray
    targets: np.ndarray
    times: np.ndarray
    steps: int
    converged: bool
    rest: np.ndarray
    timings: dict = field(default_factory=dict)
    stop_reason: str = "converged"


@dataclass(frozen=True)
class SimulationProgress:
    """What :func:`iter_simulate` yields after every time step.

    Attributes
    ----------
    step : int
        Time steps taken so far.
    shape : ndarray, shape (Na, 2)
        The current nodes ``(row, col)``.
    """

    step: int
    shape: np.ndarray


def _orientation_step(pairs: np.ndarray, nb: int) -> int:
    """+1 when the partners of a's matched nodes (in a's order) run forward
    around b, -1 when backward (the contours are oriented oppositely)."""
    if len(pairs) < 2:
        return 1
    order = np.argsort(pairs[:, 0])
    d = np.diff(pairs[order, 1]) % nb
    forward = np.minimum(d, nb - d) == d  # the shorter way round is forward
    return 1 if forward.sum() >= len(d) - forward.sum() else -1


def node_targets(a: np.ndarray, b: np.ndarray, pairs: np.ndarray, affinity: np.ndarray) -> np.ndarray:
    """Target of every node of ``a``: its partner on ``b``, or eq. 18's
    weighted target for a node without one.

    Parameters
    ----------
    a, b : ndarray, shape (Na, 2), (Nb, 2)
        Initial and target contours.
    pairs : ndarray, shape (K, 2) of int
        ``pairs[k] = (i, j)``: node ``i`` of ``a`` matches node ``j`` of ``b``.
    affinity : ndarray, shape (Na, Nb)
        Eq. 12 (0 = perfect match).

    Returns
    -------
    ndarray, shape (Na, 2)
    """
    na, nb = len(a), len(b)
    if len(pairs) == 0:
        raise ValueError("matching has no pairs: at least one node of a must be matched to simulate")
    targets = np.full((na, 2), np.nan)
    partner = np.full(na, -1)
    partner[pairs[:, 0]] = pairs[:, 1]
    targets[pairs[:, 0]] = b[pairs[:, 1]]
    unmatched = np.flatnonzero(partner < 0)
    if not len(unmatched):
        return targets
    step = _orientation_step(pairs, nb)
    matched = np.flatnonzero(partner >= 0)
    scale = np.median(affinity[affinity > 0]) if np.any(affinity > 0) else 1.0
    for i in unmatched:
        # The matched neighbours a (before) and c (after) of node i in a's order.
        prev = matched[(np.searchsorted(matched, i) - 1) % len(matched)]
        nxt = matched[np.searchsorted(matched, i) % len(matched)]
        a_p, c_p = partner[prev], partner[nxt]
        span = ((c_p - a_p) * step) % nb  # steps from a' to c' along b's order
        between = (a_p + step * np.arange(1, span)) % nb
        if len(between) == 0:
            between = np.array([a_p, c_p])
        # The higher the affinity value, the lower the weight.
        w = 1.0 / (affinity[i, between] + 1e-3 * scale)
        targets[i] = (w[:, None] * b[between]).sum(0) / w.sum()
    return targets


def _check_matching(matching, na: int, nb: int):
    pairs = np.asarray(getattr(matching, "pairs", None))
    affinity = np.asarray(getattr(matching, "affinity", None))
    if pairs.ndim != 2 or pairs.shape[1:] != (2,) or affinity.ndim != 2:
        raise ValueError("matching must be a Matching (from match()) with pairs (K, 2) and affinity (Na, Nb)")
    if affinity.shape != (na, nb) or (len(pairs) and (pairs[:, 0].max() >= na or pairs[:, 1].max() >= nb
                                                      or pairs.min() < 0)):
        raise ValueError(
            f"matching was computed for other contours: its affinity is {affinity.shape[0]} x "
            f"{affinity.shape[1]} but a has {na} nodes and b has {nb}; compute it with match(a, b)"
        )
    return pairs.astype(int), affinity


def simulate(
    a,
    b,
    matching=None,
    *,
    q: float = 30000.0,
    material: str | Material = "rubber",
    n_frames: int = 6,
    sigma_factor: float = 1.0,
    damping_ratio: float = 1.0,
    max_steps: int = 2000,
    tol: float = 0.01,
    callback=None,
) -> SimulationResult:
    """Simulate the deformation of contour ``a`` into contour ``b``.

    The rigid part of the move (a turn about ``a``'s centroid and a shift)
    carries the contour along at no elastic cost; the material resists only
    the change of shape (see ``docs/physics.md`` section 6).

    Parameters
    ----------
    a, b : (N, 2) array_like
        Initial and target contours, ``(row, col)`` nodes, closed without a
        repeated node, at least 3 nodes each.
    matching : Matching, optional
        Correspondences from :func:`match` (computed with its defaults when
        omitted). Nodes of ``a`` without a partner follow eq. 18.
    q : float, optional
        The paper's global stiffness constant (N/m) of the forces pulling each
        node toward its target (eq. 17). The integration treats them
        implicitly, so any ``q > 0`` is stable.
    material : str or Material, optional
        Virtual material of ``a``.
    n_frames : int, optional
        Frames returned (an integer, at least 2), first (``a``) and last (on
        ``b``) included.
    sigma_factor : float, optional
        Gaussian width of the element relative to ``a``'s node spacing, in
        (0, 2] (0.75-1.5 is the useful range).
    damping_ratio : float, optional
        Rayleigh damping ratio (> 0) at the lowest and highest natural
        frequencies of the body held by its target springs (1 = no overshoot).
    max_steps : int, optional
        Upper bound on time steps (an integer, at least 1).
    tol : float, optional
        At rest when no node is farther than ``tol`` px (> 0) from the
        equilibrium, the rigid move's remainder counted in.
    callback : callable, optional
        ``callback(step, shape)`` after each step; return ``False`` to stop
        (the result then has ``stop_reason="cancelled"``).

    Returns
    -------
    SimulationResult

    Raises
    ------
    ValueError
        For contours with fewer than 3 distinct nodes or NaN, contours
        spanning less than 100 times ``tol``, a matching whose node counts are
        not those of ``a`` and ``b`` (a matching of other contours with the
        same counts is not told apart), or bad parameters.

    Examples
    --------
    >>> from napari_physeg import data
    >>> from napari_physeg.core import match, simulate
    >>> a, b, _ = data.hand_pair(67, 66)
    >>> sim = simulate(a, b, match(a, b), n_frames=6)
    >>> sim.frames.shape
    (6, 67, 2)
    """
    options = {name: value for name, value in locals().items() if name not in ("a", "b", "matching", "callback")}
    check_callback(callback)

    def on_progress(state):
        # The matching computed when none is given reports as MatchingProgress: not a step.
        if callback is not None and isinstance(state, SimulationProgress):
            return callback(state.step, state.shape)

    return drain(_run(*_prepare(a, b, matching, **options)), on_progress)


def iter_simulate(a, b, matching=None, **options):
    """:func:`simulate` as a generator: one :class:`SimulationProgress` per time step.

    Takes the parameters of :func:`simulate` (but ``callback``), with its
    defaults, and returns (as ``StopIteration.value``) its
    :class:`SimulationResult`. When ``matching`` is omitted it is computed
    first with :func:`~.matching.match`'s defaults, and the generator yields
    that matching's :class:`~.matching.MatchingProgress` meanwhile. Send
    ``True`` into the generator to stop it: the result then has
    ``stop_reason="cancelled"``. Bad input raises at the call.

    Examples
    --------
    >>> from napari_physeg import data
    >>> from napari_physeg.core import match
    >>> a, b, _ = data.hand_pair(67, 66)
    >>> run = iter_simulate(a, b, match(a, b))
    >>> next(run).step
    1
    """
    arguments = with_defaults(simulate, (a, b, matching), options)  # a misspelt option fails here
    if arguments.pop("callback") is not None:
        raise TypeError("iter_simulate takes no callback: it yields its progress")
    return _run(*_prepare(**arguments))


def _prepare(a, b, matching, *, q, material, n_frames, sigma_factor, damping_ratio, max_steps, tol):
    """Check every argument of :func:`simulate` (before any heavy work)."""
    a = check_contour(a, "a")
    b = check_contour(b, "b")
    for contour, name in ((a, "a"), (b, "b")):
        warn_if_figure_eight(contour, name, "its frames follow its crossings; simulate outlines that do not cross "
                             "themselves", stacklevel=4)  # (this, _prepare, simulate, its caller)
    material = get_material(material)
    options = dict(
        q=check_number(q, "q", inclusive=False), material=material,
        n_frames=check_count(n_frames, "n_frames (first and last included)", 2),
        # As for segment(): sigma at most twice the node spacing (0.75-1.5 is the useful range).
        sigma_factor=check_number(sigma_factor, "sigma_factor", inclusive=False, maximum=2.0),
        damping_ratio=check_number(damping_ratio, "damping_ratio", inclusive=False),
        max_steps=check_count(max_steps, "max_steps", 1), tol=check_number(tol, "tol", inclusive=False))
    if matching is not None:
        _check_matching(matching, len(a), len(b))
    _check_size_for_tol(a, b, options["tol"])
    return a, b, matching, options


#: Contours must span at least this many times ``tol``: ``tol`` is in pixels,
#: and the hands in units of their size (1e-3 of them) came to rest after 6
#: steps, up to 8.8 hand-pixels from b, and said converged.
SPAN_IN_TOLS = 100.0


def _check_size_for_tol(a: np.ndarray, b: np.ndarray, tol: float) -> None:
    """A ValueError if ``a`` or ``b`` spans less than SPAN_IN_TOLS times ``tol``."""
    span = min(float(np.ptp(a, axis=0).max()), float(np.ptp(b, axis=0).max()))
    if span < SPAN_IN_TOLS * tol:
        raise ValueError(f"the contours span {span:.3g} (the smaller), less than {SPAN_IN_TOLS:g} times tol = {tol:g} "
                         "px: the rest test would stop them at once; give them in pixels, or lower tol below "
                         f"{span / SPAN_IN_TOLS:.3g}")


def _run(a, b, matching, options):
    """The steps of :func:`simulate`, as a generator (see :func:`iter_simulate`)."""
    t_start = time.perf_counter()
    q, material, n_frames = options["q"], options["material"], options["n_frames"]
    sigma_factor, damping_ratio = options["sigma_factor"], options["damping_ratio"]
    max_steps, tol = options["max_steps"], options["tol"]
    if matching is None:
        from .matching import iter_match

        matching = yield from iter_match(a, b)
        if matching.stop_reason == "cancelled":
            return _cancelled_before_start(a, t_start)
    pairs, affinity = _check_matching(matching, len(a), len(b))
    # Centred on a: the element and the springs see the shapes, not where
    # they lie (a contour at 1e10 px keeps its precision).
    given, centre = a, a.mean(axis=0)
    a, b = a - centre, b - centre
    targets = node_targets(a, b, pairs, affinity)
    carry = _RigidCarry.fit(a, targets, damping_ratio)
    model = _Model(a, carry.seen_from_a(targets), q=q, material=material, sigma_factor=sigma_factor,
                   damping_ratio=damping_ratio)
    carry.omega = model.lowest_frequency
    t_model = time.perf_counter()
    path, steps, stop_reason = yield from _evolve(a, model, carry, max_steps, tol, centre)
    frames, times = _even_frames(path, model.dt, n_frames)
    frames += centre
    frames[0] = given  # exactly
    t_end = time.perf_counter()
    return SimulationResult(
        frames=frames,
        targets=targets + centre,
        times=times,
        steps=steps,
        converged=stop_reason == "converged",
        rest=carry.moved(model.at_rest, np.inf) + centre,
        timings={"model": t_model - t_start, "evolution": t_end - t_model, "total": t_end - t_start},
        stop_reason=stop_reason,
    )


class _Model:
    """``a``'s element held by springs toward its targets, with its integrator
    and its equilibrium (where it comes to rest)."""

    def __init__(self, a, targets, *, q, material, sigma_factor, damping_ratio):
        m = len(a)
        sigma = default_sigma(a, sigma_factor)
        try:
            system = coefficient_system(a, sigma, material)
            # Every node is held by a spring of stiffness q toward its target:
            # in coefficient coordinates the nodal q I becomes q G G.
            spring = q * (system.G @ system.G)
            stiffness = sp.csc_matrix(system.K + spring)
            if m <= DENSE_NODES:
                lo, hi = natural_frequency_range(system.M, stiffness)
            else:  # the band of a reference ring: no large eigenproblem
                lo, hi = reference_frequency_range(float(np.mean(segment_lengths(a))), sigma, material, spring=q)
            mu, gamma = rayleigh_coefficients(damping_ratio, lo, hi)
            # Resolve the slowest motion with ~40 steps per period; both
            # schemes are unconditionally stable for the fast ones.
            self.dt = 2.0 * np.pi / lo / 40.0
            self.lowest_frequency = float(lo)
            if m <= DENSE_NODES:
                # Small models: exact mode superposition (the load is
                # constant) costs two small products per step.
                self.integrator = ModalIntegrator(system.M, stiffness, mu=mu, gamma=gamma, dt=self.dt)
            else:
                self.integrator = NewmarkIntegrator(system.M, stiffness, mu * system.M + gamma * stiffness,
                                                    dt=self.dt)
            # The initial contour is the rest shape (total reference): the
            # targets' pull is balanced by the elastic force of the
            # deformation from ``a``, so a stiff material (or a weak q) comes
            # to rest short of ``b``, as it should.
            gap = targets - a
            self.load = system.G @ (q * np.concatenate([gap[:, 0], gap[:, 1]]))
            U_rest = system.G @ spsolve(stiffness, self.load)
        except (np.linalg.LinAlgError, ArithmeticError) as err:
            raise _singular(err) from None
        if not (np.all(np.isfinite(U_rest)) and np.isfinite(self.dt) and self.dt > 0):
            raise _singular("non-finite equilibrium")
        self.G, self.m = system.G, m
        self.at_rest = a + np.column_stack([U_rest[:m], U_rest[m:]])

    def step(self) -> np.ndarray:
        """Displacement of every node after one more time step, ``(m, 2)``."""
        U = self.G @ self.integrator.step(self.load)
        return np.column_stack([U[: self.m], U[self.m:]])


def _singular(reason) -> ValueError:
    return ValueError(
        f"a's element is numerically singular ({reason}): some of its nodes nearly coincide or the contour "
        "folds onto itself; resample it (contour.resample) or pass fewer, evenly spaced nodes"
    )


def _evolve(a, model: _Model, carry: _RigidCarry, max_steps: int, tol: float, centre: np.ndarray):
    """Time steps until at rest (within ``tol`` of the equilibrium, the
    rigid move's remainder counted in), stopped or ``max_steps``; yields
    :class:`SimulationProgress` (shapes moved back by ``centre``), returns
    the path, the steps taken and the stop reason."""
    path = [a.copy()]
    stop_reason, steps = "max_steps", 0
    for steps in range(1, int(max_steps) + 1):
        try:
            deformed = a + model.step()
        except DivergenceError as err:  # pragma: no cover - implicit springs make this unreachable
            raise DivergenceError(f"{err} at step {steps}") from None
        if not np.all(np.isfinite(deformed)):
            raise DivergenceError(f"the simulation diverged at step {steps}")
        X = carry.moved(deformed, steps * model.dt)
        path.append(X)
        if (yield SimulationProgress(steps, X + centre)):
            stop_reason = "cancelled"
            break
        if np.abs(model.at_rest - deformed).max() + carry.left(steps * model.dt) < tol:
            stop_reason = "converged"
            break
    return np.asarray(path), steps, stop_reason


@dataclass
class _RigidCarry:
    """The rigid part of the move from ``a`` to its targets (a turn by
    ``angle`` about ``a``'s centroid, the origin, then a shift), and how far
    along it the body is at each time: as a free body held by the springs,
    whose rigid motion no elastic force resists, at the held body's lowest
    natural frequency ``omega`` and the damping ratio the run was asked for."""

    angle: float
    shift: np.ndarray
    damping_ratio: float
    reach: float  # px: how far the rigid move takes the farthest node
    omega: float = 1.0

    @classmethod
    def fit(cls, a: np.ndarray, targets: np.ndarray, damping_ratio: float) -> _RigidCarry:
        """The turn and shift that bring ``a`` (centred) closest to ``targets``
        (least squares, no reflection: the two run the same way)."""
        shift = targets.mean(axis=0)
        angle = rotation_between(a, targets - shift)
        # The farthest a node of a, or of the shape it deforms to, lies from the turn's centre.
        radius = max(float(np.hypot(*a.T).max()), float(np.hypot(*(targets - shift).T).max()))
        return cls(angle, shift, float(damping_ratio), abs(angle) * radius + float(np.hypot(*shift)))

    def seen_from_a(self, points: np.ndarray) -> np.ndarray:
        """``points`` with the whole rigid move undone: where the element must deform to."""
        return (points - self.shift) @ rotation_matrix(self.angle)

    def moved(self, points: np.ndarray, t: float) -> np.ndarray:
        """``points`` carried the share of the rigid move done at time ``t``."""
        done = 1.0 - self._remaining(t)
        return points @ rotation_matrix(done * self.angle).T + done * self.shift

    def left(self, t: float) -> float:
        """How far (px) the rigid move still has to take the farthest node at time ``t``, at most."""
        return self.reach * abs(self._remaining(t, envelope=True))

    def _remaining(self, t: float, envelope: bool = False) -> float:
        """The share of the rigid move left at time ``t``: the step response
        of a damped oscillator (``envelope``: its bound, for an underdamped one)."""
        if not np.isfinite(t):
            return 0.0
        w, z = self.omega * t, self.damping_ratio
        if abs(z - 1.0) < 1e-9:
            return (1.0 + w) * np.exp(-w)
        if z > 1.0:
            root = np.sqrt(z * z - 1.0)
            fast, slow = -(z + root), -(z - root)
            return (fast * np.exp(slow * w) - slow * np.exp(fast * w)) / (fast - slow)
        root = np.sqrt(1.0 - z * z)
        if envelope:
            return np.exp(-z * w) / root
        return np.exp(-z * w) * (np.cos(root * w) + z / root * np.sin(root * w))


def _even_frames(path: np.ndarray, dt: float, n_frames: int):
    """Frames at even intervals of the path travelled (mean node
    displacement), interpolated between the two steps that bracket each, and
    their times."""
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=2).mean(1))])
    wanted = np.linspace(0.0, travelled[-1], int(n_frames))
    after = np.clip(np.searchsorted(travelled, wanted, side="left"), 1, len(path) - 1)
    span = travelled[after] - travelled[after - 1]
    frac = np.where(span > 0, (wanted - travelled[after - 1]) / np.where(span > 0, span, 1.0), 1.0)
    frames = path[after - 1] + frac[:, None, None] * (path[after] - path[after - 1])
    frames[0], frames[-1] = path[0], path[-1]
    times = (after - 1 + frac) * dt
    times[0], times[-1] = 0.0, (len(path) - 1) * dt
    return frames, times


def _cancelled_before_start(a: np.ndarray, t_start: float) -> SimulationResult:
    """The result of a run cancelled while its matching was computed: ``a`` alone."""
    elapsed = time.perf_counter() - t_start
    return SimulationResult(frames=a[None].copy(), targets=np.full_like(a, np.nan), times=np.zeros(1), steps=0,
                            converged=False, rest=a.copy(), stop_reason="cancelled",
                            timings={"model": 0.0, "evolution": 0.0, "total": elapsed})

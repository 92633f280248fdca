"""Modal analysis of a contour's physical model (paper section 3, eq. 11).

The nodes of a contour are modelled with Sclaroff's isoparametric element
(:mod:`.element`) and the generalized eigenproblem

    K Phi = M Phi Omega                                         (eq. 11)

is solved for the lowest modes. Row ``i`` of a mode holds the displacement
``(u_i, v_i)`` of node ``i`` in that vibration mode; the low modes describe the
shape coarsely and change little under noise, small non-rigid deformations and
similarity transforms, which is what modal matching (:mod:`.matching`) uses.

Conventions (``docs/physics.md`` section 4):

* Each shape is first expressed in its own **canonical frame**: origin at the
  arc-length-weighted centroid, axes along the principal axes of the
  second moments (major axis first), unit root-mean-square radius. The sign of
  the axis with the larger normalised third moment (skewness) is chosen so that
  the skewness is positive, and the other axis completes a proper rotation (no
  reflection, so the orientation of the contour is kept). Modal displacements
  are expressed in this frame, so they rotate, translate and scale with the
  object.
* ``K`` has **no rigid-body zero modes** with Gaussian interpolants; the first
  modes mix translation and rotation into the lowest deformations and are kept.
* The number of modes is cut at a spectral gap, never through a
  near-degenerate pair (whose members are arbitrary mixtures of each other).
* Each selected mode is scaled to unit Euclidean norm over its ``2m`` entries
  and given a deterministic sign (see :func:`modal_basis`); matching still has
  to resolve the sign against the other shape.
* Up to :data:`DENSE_LIMIT` nodes the dense nodal problem is solved with
  :func:`scipy.linalg.eigh`; above it only the lowest modes are computed from
  the sparse coefficient system (same eigenvalues) with ARPACK in shift-invert
  mode and mapped back to nodal displacements with ``Phi = G phi``.
* With ``sigma`` tied to the node spacing, a model with hundreds of nodes is a
  thin band whose lowest eigenvalues lie within a few percent of each other
  (measured: the lowest 16 of a 1000-node hand within 1.4 %): its low modes
  are nearly arbitrary mixtures and change with noise and node count.
  ``model_nodes`` builds the element on a fixed number of evenly spaced nodes
  instead and interpolates the modes to the contour's nodes; matching uses 64.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg as la

from .contour import as_contour, resample
from .element import coefficient_system, default_sigma, element_matrices
from .materials import Material, get_material

__all__ = [
    "ModalBasis",
    "modal_basis",
    "canonical_frame",
    "select_modes",
    "truncate",
    "DENSE_LIMIT",
    "DEFAULT_N_MODES",
    "MAX_AUTO_MODES",
    "DEGENERACY_TOLERANCE",
]

#: Largest node count solved with the dense eigensolver.
DENSE_LIMIT = 300
#: Smallest number of modes chosen automatically.
DEFAULT_N_MODES = 6
#: Largest number of modes chosen automatically.
MAX_AUTO_MODES = 12
#: Two eigenvalues closer than this times the mean gap of the spectrum are a near-degenerate pair.
DEGENERACY_TOLERANCE = 0.25


@dataclass(frozen=True, eq=False)
class ModalBasis:
    """The lowest vibration modes of a contour in its canonical frame.

    Attributes
    ----------
    eigenvalues : ndarray, shape (n_modes,)
        Squared natural frequencies ``omega^2`` of the selected modes, ascending
        (in the canonical frame's units).
    shapes : ndarray, shape (m, n_modes, 2)
        Modal displacement ``(u, v)`` of each node in each mode, in the
        canonical frame; ``shapes[:, k, :]`` has unit Euclidean norm.
    nodes : ndarray, shape (m, 2)
        The nodes in the canonical frame (centred, principal axes, unit RMS
        radius).
    centroid : ndarray, shape (2,)
        Arc-length-weighted centroid of the input nodes, ``(row, col)``.
    axes : ndarray, shape (2, 2)
        Rows are the canonical axes as unit vectors in ``(row, col)``; a proper
        rotation (determinant +1).
    scale : float
        RMS radius of the input nodes about the centroid; canonical nodes are
        ``(nodes - centroid) @ axes.T / scale``.
    sigma : float
        Gaussian width of the element, in canonical units.
    model_nodes : int or None
        Number of evenly spaced model nodes the element was built on (None: the
        nodes themselves).
    anisotropy : float
        Ratio of the smaller to the larger principal second moment, in
        ``(0, 1]``; near 1 the principal axes are ill defined.
    skewness : ndarray, shape (2,)
        Normalised third moments along the canonical axes (after the sign fix).
    spectrum : ndarray
        All eigenvalues that were computed (at least one beyond the selection),
        used to place the cut at a spectral gap.
    material : str
        Name of the material of the element.
    """

    eigenvalues: np.ndarray
    shapes: np.ndarray
    nodes: np.ndarray
    centroid: np.ndarray
    axes: np.ndarray
    scale: float
    sigma: float
    anisotropy: float
    skewness: np.ndarray
    spectrum: np.ndarray
    material: str
    model_nodes: int | None = None

    @property
    def n_nodes(self) -> int:
        """Number of nodes ``m``."""
        return self.shapes.shape[0]

    @property
    def n_modes(self) -> int:
        """Number of selected modes."""
        return self.shapes.shape[1]

    def to_canonical(self, points) -> np.ndarray:
        """Map ``(row, col)`` points into this basis's canonical frame.

        Parameters
        ----------
        points : array_like, shape (n, 2)

        Returns
        -------
        ndarray, shape (n, 2)
        """
        return (np.asarray(points, dtype=np.float64) - self.centroid) @ self.axes.T / self.scale

    def from_canonical(self, points) -> np.ndarray:
        """Map canonical-frame points back to ``(row, col)``.

        Parameters
        ----------
        points : array_like, shape (n, 2)

        Returns
        -------
        ndarray, shape (n, 2)
        """
        return np.asarray(points, dtype=np.float64) * self.scale @ self.axes + self.centroid


def _node_weights(nodes: np.ndarray) -> np.ndarray:
    """Arc length owned by each node (half of each adjacent edge), summing to 1."""
    seg = np.linalg.norm(np.roll(nodes, -1, axis=0) - nodes, axis=1)
    w = 0.5 * (seg + np.roll(seg, 1))
    total = w.sum()
    if not total > 0:
        return np.full(len(nodes), 1.0 / len(nodes))
    return w / total


def canonical_frame(nodes):
    """Centroid, principal axes and scale of a contour, with the axis signs fixed.

    Moments are weighted by the arc length each node owns, so they describe
    the curve rather than the node density.

    Parameters
    ----------
    nodes : array_like, shape (m, 2)
        Contour nodes ``(row, col)``.

    Returns
    -------
    centroid : ndarray, shape (2,)
    axes : ndarray, shape (2, 2)
        Rows are unit axis vectors (major axis first), a proper rotation.
    scale : float
        RMS radius about the centroid.
    anisotropy : float
        Minor / major principal second moment.
    skewness : ndarray, shape (2,)
        Normalised third moments along the final axes.

    Notes
    -----
    The axis whose normalised third moment is larger in magnitude is pointed
    so that it is positive; the other axis then completes a rotation (a
    reflection would reverse the contour's orientation). When both skewnesses
    vanish (a centrally symmetric shape) the frame is defined only up to a
    half turn, which negates every modal vector and is absorbed by the
    per-mode sign correction of matching.
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    w = _node_weights(nodes)
    centroid = w @ nodes
    d = nodes - centroid
    cov = (d * w[:, None]).T @ d
    evals, evecs = np.linalg.eigh(cov)  # ascending
    axes = evecs[:, ::-1].T.copy()  # rows: major, minor
    evals = evals[::-1]
    scale = float(np.sqrt(max(evals.sum(), 1e-300)))
    anisotropy = float(max(evals[1], 0.0) / max(evals[0], 1e-300))
    q = d @ axes.T
    var = np.maximum((w[:, None] * q**2).sum(axis=0), 1e-300)
    skew = (w[:, None] * q**3).sum(axis=0) / var**1.5
    k = int(np.argmax(np.abs(skew)))
    if skew[k] < 0:
        axes[k] = -axes[k]
    if np.linalg.det(axes) < 0:
        axes[1 - k] = -axes[1 - k]
    q = d @ axes.T
    skew = (w[:, None] * q**3).sum(axis=0) / var**1.5
    return centroid, axes, scale, anisotropy, skew


def select_modes(eigenvalues, n_modes: int | None = None, *, minimum: int = DEFAULT_N_MODES,
                 maximum: int = MAX_AUTO_MODES, tolerance: float = DEGENERACY_TOLERANCE) -> int:
    """Number of modes to keep so that the cut falls at a spectral gap.

    Two consecutive eigenvalues form a near-degenerate pair when their gap is
    below ``tolerance`` times the mean gap of the computed spectrum (relative
    to the mean gap rather than to the eigenvalue, because the spectrum of this
    element has no zero modes and can be nearly flat: with many nodes the
    lowest twenty eigenvalues lie within a few percent of each other).

    Parameters
    ----------
    eigenvalues : array_like
        Ascending eigenvalues (at least one more than the largest count considered).
    n_modes : int, optional
        Requested count. It is raised, if needed, until the gap to the next
        eigenvalue is not near-degenerate (a pair is kept whole), by at most
        three modes; then the largest gap in that window is used.
    minimum, maximum : int, optional
        Range searched when ``n_modes`` is None: the first count in it whose gap
        is not near-degenerate.
    tolerance : float, optional
        See above.

    Returns
    -------
    int
        The number of modes.
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    avail = len(lam) - 1  # the cut needs the next eigenvalue
    if avail < 1:
        return len(lam)
    gaps = np.diff(lam)  # gaps[n-1] lies between mode n-1 and mode n (0-based): the cut after n modes
    mean_gap = max(float(gaps.mean()), 1e-300)

    def first_gap(lo, hi):
        lo, hi = max(1, min(lo, avail)), max(1, min(hi, avail))
        for n in range(lo, hi + 1):
            if gaps[n - 1] >= tolerance * mean_gap:
                return n
        return lo + int(np.argmax(gaps[lo - 1:hi]))

    if n_modes is not None:
        return first_gap(int(n_modes), int(n_modes) + 3)
    return first_gap(minimum, maximum)


def _lowest_modes_dense(nodes, sigma, material, k):
    M, K = element_matrices(nodes, sigma, material)
    k = min(k, K.shape[0])
    lam, phi = la.eigh(K, M, subset_by_index=[0, k - 1], check_finite=False)
    return lam, phi


def _lowest_modes_sparse(nodes, sigma, material, k):
    from scipy.sparse.linalg import eigsh

    system = coefficient_system(nodes, sigma, material)
    Kc, Mc = system.K.tocsc(), system.M.tocsc()
    # Shift slightly below zero: K is positive definite, so K - shift M is too.
    diag_ratio = float(np.median(Kc.diagonal() / Mc.diagonal()))
    shift = -1e-3 * diag_ratio
    n = Kc.shape[0]
    v0 = np.ones(n) / np.sqrt(n)
    lam, c = eigsh(Kc, k=k, M=Mc, sigma=shift, which="LM", v0=v0, tol=1e-10)
    order = np.argsort(lam)
    lam, c = lam[order], c[:, order]
    phi = system.G @ c
    return lam, np.asarray(phi)


def _cubed(values: np.ndarray) -> np.ndarray:
    """``values ** 3`` as two products: numpy's power of negative bases goes
    through the scalar ``pow``, 50 times slower (0.2-0.5 ms of each shape's
    modes, a tracked frame computes one). Only the signs of the sums of cubes
    are used, which a last-bit difference does not change (a sum within 1e-6
    of its scale falls back on the largest entry anyway)."""
    return values * values * values


def _canonical_signs(modes: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """:func:`_canonical_sign` of each mode of ``modes`` (nodes, modes, 2)."""
    moment = weights @ (_cubed(modes[..., 0]) + _cubed(modes[..., 1]))
    scale = weights @ (np.abs(modes[..., 0]) ** 3 + np.abs(modes[..., 1]) ** 3)
    signs = np.where(moment > 0, 1.0, -1.0)
    for j in np.flatnonzero(~(np.abs(moment) > 1e-6 * np.maximum(scale, 1e-300))):
        signs[j] = _canonical_sign(modes[:, j], weights)  # no third moment to go by: the largest entry
    return signs


def _canonical_sign(mode: np.ndarray, weights: np.ndarray) -> float:
    """A sign that does not depend on node numbering: the weighted third moment
    of the modal displacements made positive (largest entry as a fallback)."""
    s = float(weights @ (_cubed(mode[:, 0]) + _cubed(mode[:, 1])))
    scale = float(weights @ (np.abs(mode[:, 0]) ** 3 + np.abs(mode[:, 1]) ** 3))
    if abs(s) > 1e-6 * max(scale, 1e-300):
        return 1.0 if s > 0 else -1.0
    flat = mode.ravel()
    return 1.0 if flat[np.argmax(np.abs(flat))] >= 0 else -1.0


def _arc_positions(nodes: np.ndarray) -> np.ndarray:
    """Normalised arc-length position of each node, node 0 at 0."""
    seg = np.linalg.norm(np.roll(nodes, -1, axis=0) - nodes, axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / seg.sum()


def _modal_raw(nodes, *, n_compute: int = MAX_AUTO_MODES + 4, sigma: float | None = None,
               sigma_factor: float = 1.0, material: str | Material = "rubber",
               model_nodes: int | None = None, name: str = "nodes") -> ModalBasis:
    """All ``n_compute`` lowest modes of validated nodes, without selection."""
    nodes = np.asarray(nodes, dtype=np.float64)
    mat = get_material(material)
    centroid, axes, scale, anisotropy, skew = canonical_frame(nodes)
    canon = (nodes - centroid) @ axes.T / scale
    if sigma is not None and not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a positive number, got {sigma!r}")
    lam, modes, sigma = _canonical_modes(canon, n_compute, sigma, sigma_factor, mat, model_nodes)
    return ModalBasis(
        eigenvalues=lam,
        shapes=modes,
        nodes=canon,
        centroid=centroid,
        axes=axes,
        scale=scale,
        sigma=float(sigma),
        anisotropy=anisotropy,
        skewness=skew,
        spectrum=lam,
        material=mat.name,
        model_nodes=None if model_nodes is None else int(model_nodes),
    )


#: The modes of the last few shapes (see _canonical_modes), most recent last.
_MODES_CACHE: OrderedDict = OrderedDict()
_MODES_CACHE_SIZE = 16
_MODES_CACHE_LOCK = threading.Lock()


def _canonical_modes(canon, n_compute, sigma, sigma_factor, mat, model_nodes):
    """Eigenvalues, unit sign-fixed mode shapes at the nodes, and sigma, of
    nodes in their canonical frame (read-only arrays).

    The modes of a shape do not depend on where it lies or how it is turned,
    and tracking matches every contour twice (with the frame before and the
    frame after it), each time moved rigidly: the last few shapes' modes are
    kept, keyed on their canonical nodes to nine decimals (the two copies
    differ by rounding only).
    """
    key = (np.round(canon, 9).tobytes(), canon.shape, n_compute, sigma, sigma_factor, mat, model_nodes)
    with _MODES_CACHE_LOCK:
        if key in _MODES_CACHE:
            _MODES_CACHE.move_to_end(key)
            return _MODES_CACHE[key]
    model = canon if model_nodes is None else resample(canon, int(model_nodes))
    mm = len(model)
    if sigma is None:
        sigma = default_sigma(model, sigma_factor)
    if mm > DENSE_LIMIT:
        lam, phi = _lowest_modes_sparse(model, sigma, mat, min(n_compute, 2 * mm - 1))
    else:
        lam, phi = _lowest_modes_dense(model, sigma, mat, min(n_compute, 2 * mm))
    n = len(lam)
    modes = np.stack([phi[:mm, :n], phi[mm:, :n]], axis=-1)  # (mm, n, 2)
    if model_nodes is not None:
        # Modal displacements at the contour's nodes: linear in arc length
        # between the model nodes (which are evenly spaced from node 0).
        position = _arc_positions(canon) * mm
        below = np.minimum(position.astype(int), mm - 1)
        frac = (position - below)[:, None, None]
        closed = np.concatenate([modes, modes[:1]], axis=0)
        modes = (1.0 - frac) * closed[below] + frac * closed[below + 1]
    norms = np.sqrt((modes**2).sum(axis=(0, 2)))
    modes = modes / np.maximum(norms, 1e-300)[None, :, None]
    signs = _canonical_signs(modes, _node_weights(canon))
    lam, modes = np.ascontiguousarray(lam), np.ascontiguousarray(modes * signs[None, :, None])
    lam.setflags(write=False)
    modes.setflags(write=False)
    with _MODES_CACHE_LOCK:
        _MODES_CACHE[key] = lam, modes, sigma
        while len(_MODES_CACHE) > _MODES_CACHE_SIZE:
            _MODES_CACHE.popitem(last=False)
    return lam, modes, sigma


def truncate(basis: ModalBasis, n_modes: int) -> ModalBasis:
    """The same basis restricted to its first ``n_modes`` modes.

    Parameters
    ----------
    basis : ModalBasis
    n_modes : int
        Between 1 and ``basis.n_modes``.

    Returns
    -------
    ModalBasis

    Raises
    ------
    ValueError
        If ``n_modes`` is out of range.
    """
    n_modes = int(n_modes)
    if not 1 <= n_modes <= basis.n_modes:
        raise ValueError(f"n_modes must be between 1 and {basis.n_modes}, got {n_modes}")
    return replace(basis, eigenvalues=basis.eigenvalues[:n_modes], shapes=basis.shapes[:, :n_modes])


def modal_basis(nodes, *, n_modes: int | None = None, sigma: float | None = None,
                sigma_factor: float = 1.0, material: str | Material = "rubber",
                model_nodes: int | None = None, name: str = "nodes") -> ModalBasis:
    """The lowest vibration modes of a contour (eq. 11), in its canonical frame.

    Parameters
    ----------
    nodes : array_like, shape (m, 2)
        Contour nodes ``(row, col)``, closed implicitly, ``m >= 3``.
    n_modes : int, optional
        Number of modes. It is raised if needed so that no near-degenerate pair
        is cut; ``None`` picks 6 to 12 modes, cut at the first spectral gap.
    sigma : float, optional
        Gaussian width of the element **in canonical units** (the shape scaled
        to unit RMS radius). Default: ``sigma_factor`` times the mean
        nearest-neighbour spacing of the canonical nodes.
    sigma_factor : float, optional
        See ``sigma``; 0.75-1.5 gives a well conditioned element.
    material : str or Material, optional
        Material of the element. Only Poisson's ratio changes the mode shapes;
        the other constants scale the eigenvalues.
    model_nodes : int, optional
        Build the element on this many nodes evenly spaced along the contour
        (from node 0) instead of on the nodes themselves, and interpolate the
        modal displacements linearly in arc length to the nodes. The model's
        Gaussian width then is a fixed fraction of the perimeter, so two
        contours with different node counts get comparable modes (see
        :func:`napari_physeg.core.matching.match`). Default: the nodes
        themselves, as in the paper.
    name : str, optional
        The argument's name in error messages.

    Returns
    -------
    ModalBasis

    Raises
    ------
    ValueError
        If ``nodes`` is not a valid contour (fewer than 3 nodes, NaN, all nodes
        on a line, repeated nodes), ``n_modes`` is not a positive integer, or
        ``sigma`` makes the element singular.

    Notes
    -----
    Each mode is scaled to unit Euclidean norm and its sign is fixed by making
    the arc-length-weighted sum of ``u^3 + v^3`` positive, which does not
    depend on where the node numbering starts; it can still differ between
    two shapes, which :func:`napari_physeg.core.matching.match` corrects.

    Examples
    --------
    >>> from napari_physeg.data import hand_outline
    >>> basis = modal_basis(hand_outline("open", n_nodes=67))
    >>> basis.shapes.shape[0], basis.shapes.shape[2]
    (67, 2)
    """
    nodes = _check_nodes(nodes, name)
    if n_modes is not None:
        if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
            raise ValueError(f"n_modes must be a positive integer or None, got {n_modes!r}")
        n_modes = int(n_modes)
    n_compute = max(n_modes if n_modes is not None else MAX_AUTO_MODES, MAX_AUTO_MODES) + 4
    if model_nodes is not None:
        if isinstance(model_nodes, bool) or not isinstance(model_nodes, (int, np.integer)) or model_nodes < 8:
            raise ValueError(f"model_nodes must be an integer >= 8 or None, got {model_nodes!r}")
    raw = _modal_raw(nodes, n_compute=n_compute, sigma=sigma, sigma_factor=sigma_factor,
                     material=material, model_nodes=model_nodes, name=name)
    return truncate(raw, select_modes(raw.spectrum, n_modes))


def _check_nodes(nodes, name: str) -> np.ndarray:
    """Validate contour nodes: (m, 2), finite, >= 3 distinct, no repeated node."""
    arr = as_contour(nodes, name=name)
    raw = np.asarray(nodes, dtype=np.float64)
    if len(arr) != len(raw):
        raise ValueError(
            f"{name} has repeated consecutive nodes (or a repeated closing node): "
            f"{len(raw) - len(arr)} duplicate(s); pass each node once"
        )
    # Any two identical nodes (not only consecutive ones) make G singular.
    uniq = np.unique(arr, axis=0)
    if len(uniq) != len(arr):
        raise ValueError(f"{name} has {len(arr) - len(uniq)} identical node(s); every node must be distinct")
    return arr

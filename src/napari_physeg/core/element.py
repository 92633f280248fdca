"""Sclaroff's isoparametric finite element with Gaussian interpolants.

For ``m`` nodes ``X_k`` the element interpolates a displacement field with
``h_i(X) = sum_k a_ik g_k(X)``, ``g_k(X) = exp(-|X - X_k|^2 / (2 sigma^2))`` and
``A = G^-1`` (paper eqs. 1-4). Integrating over the plane gives closed forms for
the mass and stiffness matrices (eqs. 5-9, with the mass matrix corrected as in
``docs/physics.md``)::

    M = blockdiag(M', M'),    M' = rho h pi sigma^2  A Gamma A,   Gamma_kl = sqrt(g_kl)
    K = pi beta h  A [[B11, B12], [B12, B22]] A

Degrees of freedom are ordered ``U = [u_1..u_m, v_1..v_m]`` where ``u`` is the
displacement along the first (row) axis and ``v`` along the second (column)
axis. Because the material is isotropic the formulas are symmetric in the two
axes, so the paper's ``x`` is simply our first axis.

Two representations are provided:

* nodal matrices ``M``, ``K`` (dense), used for modal analysis and tests;
* the same system in Gaussian-coefficient coordinates ``c = A U`` (so
  ``U = G c``), where ``M~ = rho h pi sigma^2 Gamma`` and ``K~ = pi beta h B``
  need no inverse at all and are sparse once entries below ``1e-8`` of the
  diagonal are dropped. ``M U'' + C U' + K U = F`` is equivalent to
  ``M~ c'' + C~ c' + K~ c = G F``; this is what the segmentation integrates.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .contour import mean_nearest_neighbour_distance
from .materials import Material, get_material

__all__ = [
    "default_sigma",
    "gaussian_matrix",
    "interaction_kernels",
    "mass_matrix",
    "stiffness_matrix",
    "element_matrices",
    "rayleigh_coefficients",
    "CoefficientSystem",
    "coefficient_system",
    "MAX_CONDITION",
    "natural_frequency_range",
    "reference_frequency_range",
]

#: Largest accepted condition number of G; above it M loses positive definiteness.
MAX_CONDITION = 1e9
#: Relative size below which the sparse coefficient matrices drop an entry.
SPARSE_TOLERANCE = 1e-8


def default_sigma(nodes: np.ndarray, factor: float = 1.0) -> float:
    """``factor`` times the mean nearest-neighbour spacing of ``nodes``.

    ``factor`` in [0.75, 1.5] gives a well conditioned element; the interaction
    radius grows with it, and so does the condition number of ``G`` (about 1e4
    at 1 and 1e10 at 2 for evenly spaced contour nodes).
    """
    if not (np.isfinite(factor) and factor > 0):
        raise ValueError(f"sigma factor must be a positive number, got {factor!r}")
    return factor * mean_nearest_neighbour_distance(nodes)


def gaussian_matrix(nodes: np.ndarray, sigma: float) -> np.ndarray:
    """``G_kl = exp(-|X_k - X_l|^2 / (2 sigma^2))`` (eq. 3)."""
    diff = nodes[:, None, :] - nodes[None, :, :]
    return np.exp(-np.einsum("ijk,ijk->ij", diff, diff) / (2.0 * sigma**2))


def interaction_kernels(dx, dy, sigma: float, material: Material):
    """Integrals of products of Gaussians and their gradients, per node pair.

    Parameters
    ----------
    dx, dy : ndarray
        Coordinate differences ``x_k - x_l`` and ``y_k - y_l`` (any shape).
    sigma : float
        Gaussian width.
    material : Material
        Supplies ``alpha`` and ``lambda``.

    Returns
    -------
    gamma, b11, b22, b12 : ndarray
        ``Gamma = sqrt(g)`` (so that ``int g_k g_l = pi sigma^2 Gamma``) and the
        bracketed factors of eqs. 7, 8 and 9 times ``sqrt(g)`` (so that
        ``K = pi beta A [[B11, B12], [B12, B22]] A``).
    """
    s2 = 4.0 * sigma**2
    dx2, dy2 = dx * dx, dy * dy
    gamma = np.exp(-(dx2 + dy2) / s2)
    lam, alpha = material.lam, material.alpha
    half = (1.0 + lam) / 2.0
    b11 = (half - (dx2 + lam * dy2) / s2) * gamma
    b22 = (half - (dy2 + lam * dx2) / s2) * gamma
    b12 = -(alpha + lam) / s2 * dx * dy * gamma
    return gamma, b11, b22, b12


def _check_sigma(nodes: np.ndarray, sigma: float) -> None:
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a positive number, got {sigma!r}")


def _cholesky_of_g(nodes: np.ndarray, sigma: float):
    """Cholesky factor of G, refusing a sigma that makes G numerically singular."""
    _check_sigma(nodes, sigma)
    G = gaussian_matrix(nodes, sigma)
    try:
        factor = la.cho_factor(G, lower=True, check_finite=False)
    except la.LinAlgError:
        factor = None
    if factor is not None:
        rcond, info = la.lapack.dpocon(factor[0], np.abs(G).sum(axis=0).max(), uplo="L")
    if factor is None or info != 0 or rcond * MAX_CONDITION < 1.0:
        spacing = mean_nearest_neighbour_distance(nodes)
        raise ValueError(
            f"sigma = {sigma:.3g} is too large for these nodes (mean spacing {spacing:.3g}): the "
            f"Gaussian matrix G is numerically singular. Use sigma <= 1.5 x the node spacing "
            f"(sigma factor 0.75-1.5)."
        )
    return factor


def _sandwiches(cho, *Xs: np.ndarray) -> list:
    """``A X A`` of each ``X`` (m, m), with ``A = G^-1``, by Cholesky solves
    (never forming A): all the ``X`` side by side in one solve, then all the
    ``(A X)^T``. A triangular solve treats each right-hand column on its own,
    so each result is the one a solve of its own gives (bit for bit: checked
    on 800 element matrices), and one call instead of one a matrix
    costs less (scipy's checks and wrappers are most of a 64-node solve)."""
    m = len(Xs[0])
    AX = la.cho_solve(cho, np.hstack(Xs), check_finite=False)
    XA = np.hstack([AX[:, i * m:(i + 1) * m].T for i in range(len(Xs))])  # each (A X)^T
    AXA = la.cho_solve(cho, XA, check_finite=False)
    return [0.5 * (Y + Y.T) for Y in (AXA[:, i * m:(i + 1) * m] for i in range(len(Xs)))]


def element_matrices(nodes, sigma: float, material: str | Material = "rubber"):
    """Nodal mass and stiffness matrices of the element.

    Parameters
    ----------
    nodes : ndarray, shape (m, 2)
        Node coordinates ``(row, col)``.
    sigma : float
        Gaussian width (see :func:`default_sigma`).
    material : str or Material
        Preset name or material.

    Returns
    -------
    M, K : ndarray, shape (2m, 2m)
        Symmetric positive definite mass and stiffness matrices, DOFs ordered
        ``[u_1..u_m, v_1..v_m]``.

    Raises
    ------
    ValueError
        If ``sigma`` makes the Gaussian matrix numerically singular.
    """
    material = get_material(material)
    nodes = np.asarray(nodes, dtype=np.float64)
    cho = _cholesky_of_g(nodes, sigma)
    diff = nodes[:, None, :] - nodes[None, :, :]
    gamma, b11, b22, b12 = interaction_kernels(diff[..., 0], diff[..., 1], sigma, material)
    m = len(nodes)
    a_gamma, a_b11, a_b22, a_b12 = _sandwiches(cho, gamma, b11, b22, b12)
    mass = material.density * material.thickness * np.pi * sigma**2 * a_gamma
    M = np.zeros((2 * m, 2 * m))
    M[:m, :m] = M[m:, m:] = mass
    scale = np.pi * material.beta * material.thickness
    K = np.empty((2 * m, 2 * m))
    K[:m, :m] = scale * a_b11
    K[m:, m:] = scale * a_b22
    K[:m, m:] = scale * a_b12
    K[m:, :m] = K[:m, m:].T
    return M, K


def mass_matrix(nodes, sigma: float, material: str | Material = "rubber") -> np.ndarray:
    """Nodal mass matrix ``M`` (eq. 5, corrected); see :func:`element_matrices`."""
    return element_matrices(nodes, sigma, material)[0]


def stiffness_matrix(nodes, sigma: float, material: str | Material = "rubber") -> np.ndarray:
    """Nodal stiffness matrix ``K`` (eqs. 6-9); see :func:`element_matrices`."""
    return element_matrices(nodes, sigma, material)[1]


def rayleigh_coefficients(damping_ratio: float, omega_a: float, omega_b: float) -> tuple[float, float]:
    """Rayleigh coefficients ``(mu, gamma)`` of ``C = mu M + gamma K`` (eq. 10).

    Modal damping is ``xi_i = mu / (2 w_i) + gamma w_i / 2``; the returned pair
    gives ``xi = damping_ratio`` exactly at ``omega_a`` and ``omega_b`` and less
    in between.
    """
    if not (damping_ratio >= 0 and np.isfinite(damping_ratio)):
        raise ValueError(f"damping ratio must be a non-negative number, got {damping_ratio!r}")
    if not (0 < omega_a <= omega_b and np.isfinite(omega_b)):
        raise ValueError(f"need 0 < omega_a <= omega_b, got {omega_a!r}, {omega_b!r}")
    total = omega_a + omega_b
    return 2.0 * damping_ratio * omega_a * omega_b / total, 2.0 * damping_ratio / total


@dataclass(frozen=True)
class CoefficientSystem:
    """The element in Gaussian-coefficient coordinates ``c = A U``.

    Attributes
    ----------
    G : scipy.sparse matrix, shape (2m, 2m)
        ``blockdiag(G, G)``: maps coefficients to nodal displacements
        (``U = G c``) and nodal forces to coefficient forces (``G F``).
    M, K : scipy.sparse matrix, shape (2m, 2m)
        Mass and stiffness in coefficient coordinates (symmetric positive
        definite, no inverse involved).
    sigma : float
    """

    G: sp.csc_matrix
    M: sp.csc_matrix
    K: sp.csc_matrix
    sigma: float

    @property
    def n_nodes(self) -> int:
        return self.G.shape[0] // 2


def coefficient_system(nodes, sigma: float, material: str | Material = "rubber", *,
                       dense: bool = False) -> CoefficientSystem:
    """Sparse mass, stiffness and interpolation matrices in coefficient space.

    Pairs of nodes farther apart than the distance where ``sqrt(g)`` falls
    below ``1e-8`` are not stored: for evenly spaced contour nodes each node
    then interacts with about 20 others whatever the node count, which keeps
    assembling, factoring and solving linear in the number of nodes.
    ``dense=True`` gives the same matrices as ndarrays, assembled directly:
    for a small element (a hundred nodes or so) scipy.sparse's per-call
    overhead is most of the work of building and solving it.
    """
    material = get_material(material)
    nodes = np.asarray(nodes, dtype=np.float64)
    _check_sigma(nodes, sigma)
    radius = 2.0 * sigma * np.sqrt(np.log(1.0 / SPARSE_TOLERANCE))
    mass_scale = material.density * material.thickness * np.pi * sigma**2
    stiff_scale = np.pi * material.beta * material.thickness
    assemble = _dense_blocks if dense else _sparse_blocks
    G, M, K = assemble(nodes, radius, lambda dx, dy: interaction_kernels(dx, dy, sigma, material),
                       mass_scale, stiff_scale)
    return CoefficientSystem(G=G, M=M, K=K, sigma=float(sigma))


def _sparse_blocks(nodes, radius, kernels, mass_scale, stiff_scale):
    """``G``, ``M`` and ``K`` as sparse matrices over the node pairs within ``radius``."""
    m = len(nodes)
    pairs = cKDTree(nodes).query_pairs(radius, output_type="ndarray")
    diag = np.arange(m)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1], diag])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0], diag])
    diff = nodes[rows] - nodes[cols]
    gamma, b11, b22, b12 = kernels(diff[:, 0], diff[:, 1])

    def blocks(tl, br, off=None):
        r = np.concatenate([rows, rows + m] + ([rows, rows + m] if off is not None else []))
        c = np.concatenate([cols, cols + m] + ([cols + m, cols] if off is not None else []))
        v = np.concatenate([tl, br] + ([off, off] if off is not None else []))
        return sp.csc_matrix((v, (r, c)), shape=(2 * m, 2 * m))

    return (blocks(gamma**2, gamma**2), blocks(mass_scale * gamma, mass_scale * gamma),
            blocks(stiff_scale * b11, stiff_scale * b22, stiff_scale * b12))


def _dense_blocks(nodes, radius, kernels, mass_scale, stiff_scale):
    """``G``, ``M`` and ``K`` as ndarrays, with the same pairs as :func:`_sparse_blocks`."""
    diff = nodes[:, None, :] - nodes[None, :, :]
    within = (diff**2).sum(-1) <= radius**2
    gamma, b11, b22, b12 = (k * within for k in kernels(diff[..., 0], diff[..., 1]))
    zero = np.zeros_like(gamma)
    return (np.block([[gamma**2, zero], [zero, gamma**2]]),
            mass_scale * np.block([[gamma, zero], [zero, gamma]]),
            stiff_scale * np.block([[b11, b12], [b12, b22]]))


def natural_frequency_range(M, K) -> tuple[float, float]:
    """Lowest and highest natural frequencies ``w = sqrt(eig(K, M))`` (rad/s).

    Dense solve for small systems, ARPACK (shift-invert for the lowest) for
    large sparse ones.
    """
    n = M.shape[0]
    if n <= 600:
        Md = M.toarray() if sp.issparse(M) else M
        Kd = K.toarray() if sp.issparse(K) else K
        w2 = la.eigh(Kd, Md, eigvals_only=True)
        lo, hi = w2[0], w2[-1]
    else:
        from scipy.sparse.linalg import eigsh

        hi = eigsh(sp.csc_matrix(K), k=1, M=sp.csc_matrix(M), which="LM", return_eigenvectors=False)[0]
        lo = eigsh(sp.csc_matrix(K), k=1, M=sp.csc_matrix(M), sigma=0.0, which="LM",
                   return_eigenvectors=False)[0]
    return float(np.sqrt(max(lo, 1e-300))), float(np.sqrt(hi))


def reference_frequency_range(spacing: float, sigma: float, material: str | Material = "rubber",
                              n_nodes: int = 64, spring: float = 0.0) -> tuple[float, float]:
    """Natural frequency range of a ring of ``n_nodes`` nodes at ``spacing``.

    The element's stiffness does not depend on scale and its mass grows with
    ``sigma^2``, so the frequency band of a contour's local modes is set by
    the material, the node spacing and ``sigma``, not by the contour's size.
    A small reference ring gives that band for the price of a 128 x 128
    eigenproblem (solved once per material and ``sigma / spacing``, then
    rescaled), whatever the model's node count; it sets the Rayleigh damping
    of segmentation models. ``spring`` adds a stiffness (N/m) tying every
    node to a fixed point, as the simulation's target forces do.
    """
    lo, hi = _unit_ring_frequencies(round(sigma / spacing, 9), get_material(material), int(n_nodes),
                                    float(spring))
    # All lengths scale with the spacing: K is unchanged, M grows as spacing^2.
    return lo / spacing, hi / spacing


@lru_cache(maxsize=64)
def _unit_ring_frequencies(sigma: float, material: Material, n_nodes: int,
                           spring: float) -> tuple[float, float]:
    radius = 1.0 / (2.0 * np.sin(np.pi / n_nodes))
    t = 2.0 * np.pi * np.arange(n_nodes) / n_nodes
    ring = radius * np.column_stack([np.cos(t), np.sin(t)])
    M, K = element_matrices(ring, sigma, material)
    return natural_frequency_range(M, K + spring * np.eye(len(K)))

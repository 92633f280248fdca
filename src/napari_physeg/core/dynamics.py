"""Time integration of the dynamic equilibrium equation ``M U'' + C U' + K U = F``.

Two unconditionally stable schemes (paper eq. 13, see ``docs/physics.md`` §2):

* :class:`NewmarkIntegrator` - Newmark's method; with the default trapezoidal
  constants (``delta = 1/2, alpha = 1/4``) it is unconditionally stable and
  second order. The effective stiffness ``K + a0 M + a1 C`` is factored once, so
  each step costs two triangular solves (a sparse LU for sparse systems).
* :class:`ModalIntegrator` - mode superposition: with M-orthonormal modes and
  Rayleigh damping the equations decouple and every mode is advanced exactly
  for a force held constant over the step; keeping only the lowest modes is
  Nastar's fast scheme.

Both keep the state ``(U, V, A)`` and expose :meth:`step`. For an *updated*
(incremental) reference, call :meth:`rebase` after a step: the current shape
becomes the rest shape (``U := 0``) while velocity and acceleration carry on.

A step whose result is not finite, or whose displacement grows beyond any
sensible bound, raises :class:`DivergenceError`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["DivergenceError", "NewmarkIntegrator", "ModalIntegrator", "newmark_constants"]


class DivergenceError(RuntimeError):
    """The integration produced non-finite or exploding displacements."""


def newmark_constants(dt: float, delta: float = 0.5, alpha: float = 0.25) -> tuple[float, ...]:
    """Bathe's integration constants ``a0..a7`` for Newmark's method.

    The scheme is unconditionally stable for ``delta >= 1/2`` and
    ``alpha >= (delta + 1/2)^2 / 4``; ``delta > 1/2`` adds numerical damping of
    the highest modes.
    """
    if not (dt > 0 and np.isfinite(dt)):
        raise ValueError(f"time step dt must be a positive number, got {dt!r}")
    if delta < 0.5 or alpha < 0.25 * (0.5 + delta) ** 2:
        raise ValueError(
            f"Newmark constants delta={delta}, alpha={alpha} are not unconditionally stable: "
            "need delta >= 0.5 and alpha >= (delta + 0.5)**2 / 4"
        )
    a0 = 1.0 / (alpha * dt**2)
    a1 = delta / (alpha * dt)
    a2 = 1.0 / (alpha * dt)
    a3 = 1.0 / (2.0 * alpha) - 1.0
    a4 = delta / alpha - 1.0
    a5 = dt / 2.0 * (delta / alpha - 2.0)
    a6 = dt * (1.0 - delta)
    a7 = delta * dt
    return a0, a1, a2, a3, a4, a5, a6, a7


def _check_state(U: np.ndarray, limit: float) -> None:
    peak = float(np.abs(U).max()) if U.size else 0.0  # NaN or inf if any is (one pass: runs every step)
    if not np.isfinite(peak):
        raise DivergenceError("the dynamic equilibrium equation diverged (non-finite displacement)")
    if limit and peak > limit:
        raise DivergenceError(f"the dynamic equilibrium equation diverged (displacement {peak:.3g} > {limit:.3g})")


class NewmarkIntegrator:
    """Newmark time stepping for ``M U'' + C U' + K U = F``.

    Parameters
    ----------
    M, K : ndarray or sparse matrix, shape (n, n)
        Symmetric positive definite mass and stiffness.
    C : ndarray or sparse matrix, optional
        Damping matrix (default: none).
    dt : float
        Time step.
    delta, alpha : float
        Newmark constants (default: trapezoidal rule).
    divergence_limit : float, optional
        Raise :class:`DivergenceError` when ``|U|`` exceeds it (0 disables).
    """

    def __init__(self, M, K, C=None, *, dt: float = 1.0, delta: float = 0.5, alpha: float = 0.25,
                 divergence_limit: float = 0.0):
        self.constants = newmark_constants(dt, delta, alpha)
        a0, a1 = self.constants[:2]
        self.dt = float(dt)
        self.M, self.K = M, K
        self.C = C if C is not None else (sp.csc_matrix(M.shape) if sp.issparse(M) else np.zeros(M.shape))
        effective = K + a0 * M + a1 * self.C
        if sp.issparse(effective):
            # Symmetric positive definite: a symmetric ordering and no pivoting
            # factor it about a third faster than SuperLU's defaults.
            lu = spla.splu(sp.csc_matrix(effective), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
            self._solve = lu.solve
        else:
            # Dense systems come from small elements (segmentation.DENSE_MAX_NODES;
            # larger ones are sparse): the inverse, formed once, turns every
            # step's solve into one matrix-vector product; scipy's cho_solve
            # spent more time checking its arguments than solving.
            cho = la.cho_factor(0.5 * (effective + effective.T), check_finite=False)
            inverse = la.cho_solve(cho, np.eye(len(effective)), check_finite=False)
            self._solve = inverse.__matmul__
        n = M.shape[0]
        self.U = np.zeros(n)
        self.V = np.zeros(n)
        self.A = np.zeros(n)
        self.divergence_limit = divergence_limit

    def from_rest(self, F: np.ndarray) -> np.ndarray:
        """Displacement after one step under ``F`` of the body starting at rest
        in its rest shape (``U = V = A = 0``); the state is not changed."""
        U = self._solve(F)
        _check_state(U, self.divergence_limit)
        return U

    def trial(self, F: np.ndarray) -> np.ndarray:
        """The displacement :meth:`step` would reach under ``F``, without advancing."""
        a0, a1, a2, a3, a4, a5 = self.constants[:6]
        U, V, A = self.U, self.V, self.A
        rhs = F + self.M @ (a0 * U + a2 * V + a3 * A) + self.C @ (a1 * U + a4 * V + a5 * A)
        return self._solve(rhs)

    def step(self, F: np.ndarray) -> np.ndarray:
        """Advance one step under the force ``F`` at the end of the step; return ``U``."""
        a0, a1, a2, a3, a4, a5, a6, a7 = self.constants
        U, V, A = self.U, self.V, self.A
        U_new = self.trial(F)
        _check_state(U_new, self.divergence_limit)
        A_new = a0 * (U_new - U) - a2 * V - a3 * A
        self.V = V + a6 * A + a7 * A_new
        self.A = A_new
        self.U = U_new
        return U_new

    def rebase(self) -> None:
        """Make the current shape the rest shape (incremental reference)."""
        self.U = np.zeros_like(self.U)

    def reset(self) -> None:
        """Bring the body to rest in its current shape (U, V, A := 0)."""
        self.U, self.V, self.A = (np.zeros_like(self.U) for _ in range(3))


class ModalIntegrator:
    """Mode superposition for ``M U'' + C U' + K U = F`` with Rayleigh damping.

    Parameters
    ----------
    M, K : ndarray, shape (n, n)
        Symmetric positive definite mass and stiffness (sparse input is densified).
    mu, gamma : float
        Rayleigh coefficients of ``C = mu M + gamma K``.
    dt : float
        Time step.
    n_modes : int, optional
        Keep only the lowest ``n_modes`` modes (default: all).
    divergence_limit : float, optional
        As for :class:`NewmarkIntegrator`.

    Notes
    -----
    Mode ``i`` obeys ``q'' + (mu + gamma w_i^2) q' + w_i^2 q = phi_i^T F``. For a
    force held constant over the step the update ``[q, q'] -> [q, q']`` is
    exact: ``x(t + dt) = x_s + exp(S dt) (x(t) - x_s)``, with ``x_s`` the static
    solution of the mode, so the scheme is stable for any ``dt``.
    """

    def __init__(self, M, K, *, mu: float = 0.0, gamma: float = 0.0, dt: float = 1.0,
                 n_modes: int | None = None, divergence_limit: float = 0.0):
        if not (dt > 0 and np.isfinite(dt)):
            raise ValueError(f"time step dt must be a positive number, got {dt!r}")
        M = M.toarray() if sp.issparse(M) else np.asarray(M)
        K = K.toarray() if sp.issparse(K) else np.asarray(K)
        n = M.shape[0]
        subset = None if n_modes is None else (0, min(int(n_modes), n) - 1)
        omega2, phi = la.eigh(0.5 * (K + K.T), 0.5 * (M + M.T), subset_by_index=subset)
        self.omega = np.sqrt(np.maximum(omega2, 0.0))
        self.phi = phi  # M-orthonormal
        damping = mu + gamma * omega2
        # Per-mode state matrix S = [[0, 1], [-w^2, -c]] and its exponential.
        S = np.zeros((len(omega2), 2, 2))
        S[:, 0, 1] = 1.0
        S[:, 1, 0] = -omega2
        S[:, 1, 1] = -damping
        self._propagator = la.expm(S * dt)
        self._omega2 = omega2
        self.q = np.zeros((len(omega2), 2))
        self.dt = float(dt)
        self.divergence_limit = divergence_limit

    @property
    def U(self) -> np.ndarray:
        return self.phi @ self.q[:, 0]

    def _advance(self, F: np.ndarray) -> np.ndarray:
        static = (self.phi.T @ F) / self._omega2
        x = self.q.copy()
        x[:, 0] -= static
        x = np.einsum("mij,mj->mi", self._propagator, x)
        x[:, 0] += static
        return x

    def trial(self, F: np.ndarray) -> np.ndarray:
        """The displacement :meth:`step` would reach under ``F``, without advancing."""
        return self.phi @ self._advance(F)[:, 0]

    def from_rest(self, F: np.ndarray) -> np.ndarray:
        """Displacement after one step under ``F`` from rest; the state is not changed."""
        static = (self.phi.T @ F) / self._omega2
        # From x = 0: x(dt) = x_s - exp(S dt) x_s, and only q (not q') is needed.
        U = self.phi @ (static * (1.0 - self._propagator[:, 0, 0]))
        _check_state(U, self.divergence_limit)
        return U

    def step(self, F: np.ndarray) -> np.ndarray:
        """Advance one step under ``F`` held over the step; return ``U``."""
        self.q = self._advance(F)
        U = self.U
        _check_state(U, self.divergence_limit)
        return U

    def rebase(self) -> None:
        """Make the current shape the rest shape (incremental reference)."""
        # Only the modal displacements reset; modal velocities carry on.
        self.q[:, 0] = 0.0

    def reset(self) -> None:
        """Bring the body to rest in its current shape."""
        self.q[:] = 0.0

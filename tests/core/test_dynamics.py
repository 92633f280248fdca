"""Integrators of M U'' + C U' + K U = F against analytic solutions and each other."""

import numpy as np
import pytest
import scipy.sparse as sp

from napari_physeg.core.dynamics import DivergenceError, ModalIntegrator, NewmarkIntegrator
from napari_physeg.core.element import (
    coefficient_system,
    default_sigma,
    element_matrices,
    rayleigh_coefficients,
)


def _damped_oscillator(t, m, c, k, f):
    """Analytic response of m x'' + c x' + k x = f from rest (underdamped)."""
    w0 = np.sqrt(k / m)
    xi = c / (2 * np.sqrt(k * m))
    wd = w0 * np.sqrt(1 - xi**2)
    xs = f / k
    return xs * (1 - np.exp(-xi * w0 * t) * (np.cos(wd * t) + xi * w0 / wd * np.sin(wd * t)))


@pytest.mark.parametrize("integrator", ["newmark", "modal"])
def test_single_dof_damped_oscillator_matches_analytic_solution(integrator):
    m, c, k, f = 2.0, 0.6, 50.0, 3.0
    M, K = np.array([[m]]), np.array([[k]])
    dt, n = 0.002, 2000
    if integrator == "newmark":
        sim = NewmarkIntegrator(M, K, np.array([[c]]), dt=dt)
        sim.A[:] = f / m  # consistent initial acceleration under a step load
    else:
        sim = ModalIntegrator(M, K, mu=c / m, dt=dt)  # C = mu M
    x = np.array([sim.step(np.array([f]))[0] for _ in range(n)])
    t = dt * np.arange(1, n + 1)
    exact = _damped_oscillator(t, m, c, k, f)
    tol = 1e-4 if integrator == "newmark" else 1e-10  # modal stepping is exact for constant F
    assert np.abs(x - exact).max() <= tol * abs(f / k) * 10


def _small_element(n=16, material="rubber"):
    t = 2 * np.pi * np.arange(n) / n
    nodes = 10 * np.column_stack([np.cos(t), 1.3 * np.sin(t)])
    return element_matrices(nodes, default_sigma(nodes), material), nodes


def test_static_limit_is_k_inverse_f():
    (M, K), nodes = _small_element()
    w = np.sqrt(np.linalg.eigvalsh(np.linalg.solve(M, K)))
    mu, gamma = rayleigh_coefficients(1.0, w.min(), w.max())
    F = np.random.default_rng(0).normal(size=K.shape[0]) * 100
    expected = np.linalg.solve(K, F)
    for sim in (
        NewmarkIntegrator(M, K, mu * M + gamma * K, dt=5 / w.min()),
        ModalIntegrator(M, K, mu=mu, gamma=gamma, dt=5 / w.min()),
    ):
        for _ in range(400):
            U = sim.step(F)
        assert np.allclose(U, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())


def test_newmark_and_modal_agree_on_an_element():
    (M, K), nodes = _small_element(material="copper")
    w = np.sqrt(np.linalg.eigvalsh(np.linalg.solve(M, K)))
    mu, gamma = rayleigh_coefficients(0.05, w.min(), w.max())
    dt = 0.02 / w.max()
    F = np.zeros(K.shape[0])
    F[0] = 1e3
    nm = NewmarkIntegrator(M, K, mu * M + gamma * K, dt=dt)
    md = ModalIntegrator(M, K, mu=mu, gamma=gamma, dt=dt)
    for _ in range(300):
        a, b = nm.step(F), md.step(F)
    assert np.allclose(a, b, rtol=2e-3, atol=2e-3 * np.abs(b).max())


def test_coefficient_space_trajectory_equals_nodal_trajectory():
    """U = G c: integrating in Gaussian-coefficient coordinates changes nothing."""
    (M, K), nodes = _small_element(12)
    sigma = default_sigma(nodes)
    cs = coefficient_system(nodes, sigma, "rubber")
    rng = np.random.default_rng(2)
    nodal = NewmarkIntegrator(M, K, 0.1 * M + 1e-3 * K, dt=0.01)
    coeff = NewmarkIntegrator(cs.M, cs.K, 0.1 * cs.M + 1e-3 * cs.K, dt=0.01)
    for _ in range(50):
        F = rng.normal(size=K.shape[0])
        U = nodal.step(F)
        c = coeff.step(cs.G @ F)
    assert np.allclose(cs.G @ c, U, rtol=1e-6, atol=1e-8 * np.abs(U).max())


def test_unconditional_stability_with_huge_time_step():
    (M, K), _ = _small_element(material="copper")
    F = np.ones(K.shape[0]) * 1e5
    sim = NewmarkIntegrator(M, K, dt=1e3)
    for _ in range(100):
        U = sim.step(F)
    assert np.abs(U).max() < 3 * np.abs(np.linalg.solve(K, F)).max()


def test_divergence_is_reported():
    M = K = sp.identity(3, format="csc")
    sim = NewmarkIntegrator(M, K, dt=1.0, divergence_limit=10.0)
    with pytest.raises(DivergenceError, match="diverged"):
        sim.step(np.array([1e3, 0, 0]))
    with pytest.raises(DivergenceError, match="non-finite"):
        NewmarkIntegrator(M, K, dt=1.0).step(np.array([np.nan, 0, 0]))


def test_rebase_resets_elastic_memory():
    """With an updated reference a constant force keeps moving the body."""
    (M, K), _ = _small_element()
    F = np.ones(K.shape[0]) * 100
    w = np.sqrt(np.linalg.eigvalsh(np.linalg.solve(M, K)))
    mu, gamma = rayleigh_coefficients(1.0, w.min(), w.max())
    C, dt = mu * M + gamma * K, 2 / w.min()
    total, incremental = NewmarkIntegrator(M, K, C, dt=dt), NewmarkIntegrator(M, K, C, dt=dt)
    moved = np.zeros_like(F)
    for _ in range(200):
        total.step(F)
        moved += incremental.step(F)
        incremental.rebase()
    static = np.linalg.solve(K, F)
    assert np.allclose(total.U, static, rtol=1e-3)
    assert np.abs(moved).max() > 50 * np.abs(static).max()


def test_bad_newmark_constants_rejected():
    M = K = np.eye(2)
    with pytest.raises(ValueError, match="unconditionally stable"):
        NewmarkIntegrator(M, K, delta=0.5, alpha=0.1)
    with pytest.raises(ValueError, match="dt"):
        NewmarkIntegrator(M, K, dt=0)


@pytest.mark.parametrize("kind", ["newmark", "modal"])
def test_from_rest_equals_a_step_after_reset(kind):
    (M, K), _ = _small_element()
    w = np.sqrt(np.linalg.eigvalsh(np.linalg.solve(M, K)))
    mu, gamma = rayleigh_coefficients(1.0, w.min(), w.max())
    F = np.random.default_rng(5).normal(size=K.shape[0])
    if kind == "newmark":
        sim = NewmarkIntegrator(M, K, mu * M + gamma * K, dt=0.3 / w.min())
    else:
        sim = ModalIntegrator(M, K, mu=mu, gamma=gamma, dt=0.3 / w.min())
    sim.step(F * 3)  # some state that from_rest must ignore
    U = sim.from_rest(F)
    sim.reset()
    assert np.allclose(U, sim.step(F), rtol=1e-10, atol=1e-14)

"""Sclaroff's element: closed forms against quadrature, and physical properties."""

import numpy as np
import pytest
import scipy.linalg as la
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from napari_physeg.core.element import (
    SPARSE_TOLERANCE,
    coefficient_system,
    default_sigma,
    element_matrices,
    gaussian_matrix,
    rayleigh_coefficients,
)
from napari_physeg.core.materials import MATERIALS, Material


def _quadrature(nodes, sigma, material, spacing=0.08, margin=9.0):
    """rho h int H^T H and h int B^T D B by brute force on a fine grid.

    Gaussians are smooth and decay fast, so the rectangle rule converges
    spectrally: with spacing ~ sigma/12 it is exact to ~1e-12.
    """
    lo = nodes.min(axis=0) - margin * sigma
    hi = nodes.max(axis=0) + margin * sigma
    xs = np.arange(lo[0], hi[0], spacing)
    ys = np.arange(lo[1], hi[1], spacing)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel()])
    A = np.linalg.inv(gaussian_matrix(nodes, sigma))
    d = P[:, None, :] - nodes[None, :, :]
    g = np.exp(-(d**2).sum(-1) / (2 * sigma**2))  # (P, m)
    h = g @ A  # interpolants h_i at the points (A symmetric)
    hx = (-(d[..., 0]) / sigma**2 * g) @ A
    hy = (-(d[..., 1]) / sigma**2 * g) @ A
    w = spacing**2
    m = len(nodes)
    t = material.thickness
    M = np.zeros((2 * m, 2 * m))
    M[:m, :m] = M[m:, m:] = material.density * t * w * h.T @ h
    a, lam, beta = material.alpha, material.lam, material.beta
    # strain = [u_x, v_y, u_y + v_x]; B = [[hx, 0], [0, hy], [hy, hx]]
    zero = np.zeros_like(hx)
    B = np.stack([np.hstack([hx, zero]), np.hstack([zero, hy]), np.hstack([hy, hx])])  # (3, P, 2m)
    D = beta * np.array([[1, a, 0], [a, 1, 0], [0, 0, lam]])
    K = t * w * np.einsum("ipk,ij,jpl->kl", B, D, B)
    return M, K


@pytest.mark.parametrize("material", ["rubber", "copper"])
def test_closed_form_matches_quadrature(material):
    rng = np.random.default_rng(1)
    nodes = rng.uniform(0, 3, size=(5, 2))
    mat = MATERIALS[material].with_(thickness=1.0)
    sigma = 1.0
    M, K = element_matrices(nodes, sigma, mat)
    Mq, Kq = _quadrature(nodes, sigma, mat)
    assert np.abs(M - Mq).max() <= 1e-10 * np.abs(M).max()
    assert np.abs(K - Kq).max() <= 1e-10 * np.abs(K).max()


def test_plane_strain_matches_quadrature():
    nodes = np.array([[0.0, 0.0], [1.2, 0.3], [0.4, 1.5], [-0.7, 0.9]])
    mat = Material("x", young=1.0, poisson=0.3, density=1.0, thickness=1.0, plane="strain")
    M, K = element_matrices(nodes, 0.9, mat)
    _, Kq = _quadrature(nodes, 0.9, mat)
    assert np.abs(K - Kq).max() <= 1e-10 * np.abs(K).max()


def _circle(n, radius=20.0):
    t = 2 * np.pi * np.arange(n) / n
    return radius * np.column_stack([np.cos(t), np.sin(t)])


def test_mass_and_stiffness_symmetric_positive_definite():
    nodes = _circle(60) + np.array([3.0, -7.0])
    M, K = element_matrices(nodes, default_sigma(nodes), "rubber")
    for X in (M, K):
        assert np.array_equal(X, X.T)
        la.cholesky(X)  # raises if not positive definite
    # No rigid-body zero modes: Gaussians are not a partition of unity.
    w = la.eigh(K, M, eigvals_only=True)
    assert w[0] > 0


def test_stiffness_translation_invariant_and_rotation_covariant():
    rng = np.random.default_rng(3)
    nodes = _circle(40) + rng.normal(scale=0.5, size=(40, 2))
    sigma = default_sigma(nodes)
    K = element_matrices(nodes, sigma, "copper")[1]
    K_shift = element_matrices(nodes + [100.0, -250.0], sigma, "copper")[1]
    assert np.allclose(K_shift, K, rtol=1e-9, atol=1e-9 * np.abs(K).max())
    theta = 0.7
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    K_rot = element_matrices(nodes @ R.T, sigma, "copper")[1]
    m = len(nodes)
    T = np.kron(R, np.eye(m))  # rotates every node's (u, v) pair
    assert np.allclose(K_rot, T @ K @ T.T, rtol=1e-8, atol=1e-8 * np.abs(K).max())
    # and K is *not* invariant to rotation alone (the test can fail)
    assert not np.allclose(K_rot, K, atol=1e-3 * np.abs(K).max())


def test_coefficient_system_equals_nodal_system():
    nodes = _circle(50)
    sigma = default_sigma(nodes)
    M, K = element_matrices(nodes, sigma, "rubber")
    cs = coefficient_system(nodes, sigma, "rubber")
    G = cs.G.toarray()
    A = np.linalg.inv(G)
    # M = A M~ A and K = A K~ A, up to the entries the sparse form drops
    # (below SPARSE_TOLERANCE of the diagonal, amplified by A's norm).
    tol = 100 * SPARSE_TOLERANCE
    assert np.abs(A @ cs.M.toarray() @ A - M).max() <= tol * np.abs(M).max()
    assert np.abs(A @ cs.K.toarray() @ A - K).max() <= tol * np.abs(K).max()
    # sparse: each node interacts with a bounded neighbourhood
    assert cs.K.nnz < 0.8 * (2 * len(nodes)) ** 2


@pytest.mark.parametrize("material", ["rubber", "copper"])
def test_dense_coefficient_system_is_the_sparse_one(material):
    # An irregular contour long enough that distant node pairs are dropped.
    rng = np.random.default_rng(3)
    nodes = _circle(80) * np.array([1.0, 0.4]) + rng.normal(0.0, 0.05, (80, 2))
    sigma = default_sigma(nodes)
    sparse = coefficient_system(nodes, sigma, material)
    dense = coefficient_system(nodes, sigma, material, dense=True)
    assert sparse.K.nnz < 0.8 * (2 * len(nodes)) ** 2  # the cut-off matters here
    for name in ("G", "M", "K"):
        assert isinstance(getattr(dense, name), np.ndarray)
        assert np.array_equal(getattr(sparse, name).toarray(), getattr(dense, name)), name


def test_sigma_too_large_is_rejected_with_a_clear_message():
    nodes = _circle(100)
    with pytest.raises(ValueError, match="sigma .* too large"):
        element_matrices(nodes, 3 * default_sigma(nodes), "rubber")


def test_rayleigh_coefficients_give_requested_damping():
    mu, gamma = rayleigh_coefficients(0.3, 2.0, 50.0)
    for w in (2.0, 50.0):
        assert mu / (2 * w) + gamma * w / 2 == pytest.approx(0.3)
    with pytest.raises(ValueError, match="damping"):
        rayleigh_coefficients(-1, 1, 2)


@settings(max_examples=40, deadline=None)
@given(
    nodes=arrays(np.float64, (6, 2), elements=st.floats(-30, 30, allow_nan=False)),
    material=st.sampled_from(sorted(MATERIALS)),
)
def test_element_finite_and_symmetric_for_random_nodes(nodes, material):
    nodes = np.unique(np.round(nodes, 1), axis=0)
    if len(nodes) < 3:
        return
    try:
        sigma = default_sigma(nodes)
        M, K = element_matrices(nodes, sigma, material)
    except ValueError as err:  # only a refused sigma is acceptable
        assert "sigma" in str(err)
        return
    for X in (M, K):
        assert np.all(np.isfinite(X))
        assert np.array_equal(X, X.T)
    assert np.linalg.eigvalsh(K).min() > -1e-9 * np.abs(K).max()


def test_reference_frequency_range_scales_with_spacing():
    from napari_physeg.core.element import natural_frequency_range, reference_frequency_range

    lo1, hi1 = reference_frequency_range(1.0, 1.0, "rubber")
    lo3, hi3 = reference_frequency_range(3.0, 3.0, "rubber")
    assert lo3 == pytest.approx(lo1 / 3) and hi3 == pytest.approx(hi1 / 3)
    t = 2 * np.pi * np.arange(64) / 64
    ring = 3.0 / (2 * np.sin(np.pi / 64)) * np.column_stack([np.cos(t), np.sin(t)])
    direct = natural_frequency_range(*element_matrices(ring, 3.0, "rubber"))
    assert np.allclose(direct, (lo3, hi3), rtol=1e-8)
    assert reference_frequency_range(1.0, 1.0, "copper")[1] > 5 * hi1  # stiffer, higher

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from surface_strain import (
    area_ratio,
    compute_strain,
    deformation_gradient,
    delaunay_triangles,
    directional_components,
    euler_almansi,
    green_lagrange,
    logarithmic_strain,
    principal_strains,
    reference_frames,
)
from tests.tolerances import EXACT

GRID = np.stack(np.meshgrid(np.linspace(200, 600, 7), np.linspace(200, 600, 7)), -1).reshape(-1, 2)
TRI = delaunay_triangles(GRID)


def rot2(a):
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def random_rotation3(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize(
    ("A", "E_true"),
    [
        (np.diag([1.5, 1.5]), [[0.625, 0], [0, 0.625]]),  # paper eqs. 3-6
        (rot2(np.radians(30)), [[0, 0], [0, 0]]),  # eqs. 7-9
        (np.array([[1, 0.5], [0, 1]]), [[0, 0.25], [0.25, 0.125]]),  # eqs. 10-13
        (np.diag([0.6, 0.6]), [[-0.32, 0], [0, -0.32]]),  # tissue contraction
    ],
    ids=["equibiaxial", "rotation", "shear", "contraction"],
)
def test_paper_cases_exact(A, E_true):
    c = np.array([400.0, 400.0])
    x = c + (GRID - c) @ A.T
    field = compute_strain(GRID, x[None], TRI)
    np.testing.assert_allclose(field.E[0], np.broadcast_to(E_true, field.E[0].shape), atol=EXACT)
    np.testing.assert_allclose(
        field.nodal_E[0], np.broadcast_to(E_true, field.nodal_E[0].shape), atol=EXACT
    )
    np.testing.assert_allclose(field.F[0], np.broadcast_to(A, field.F[0].shape), atol=EXACT)


def test_deformation_gradient_is_identity_plus_displacement_gradient():
    rng = np.random.default_rng(1)
    grad_u = rng.normal(scale=0.2, size=(2, 2))
    x = GRID + GRID @ grad_u.T + [3.0, -7.0]
    F = deformation_gradient(GRID, x, TRI)
    np.testing.assert_allclose(F, np.broadcast_to(np.eye(2) + grad_u, F.shape), atol=EXACT)


@pytest.mark.parametrize("seed", range(5))
def test_rigid_motion_2d_gives_zero_strain(seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 500, (40, 2))
    tri = delaunay_triangles(pts)
    frames = np.stack([pts @ rot2(a).T + rng.uniform(-100, 100, 2) for a in rng.uniform(-3, 3, 6)])
    field = compute_strain(pts, frames, tri)
    assert np.abs(field.E).max() < EXACT
    np.testing.assert_allclose(area_ratio(field.F), 1.0, atol=EXACT)


@pytest.mark.parametrize("seed", range(5))
def test_rigid_motion_3d_curved_surface_gives_zero_strain(seed):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1, 1, (60, 2))
    pts = np.column_stack([xy, 0.4 * np.sin(2 * xy[:, 0]) * np.cos(xy[:, 1])])  # curved sheet
    tri = delaunay_triangles(pts)
    moved = np.stack([pts @ random_rotation3(rng).T + rng.normal(size=3) for _ in range(4)])
    field = compute_strain(pts, moved, tri)
    assert np.abs(field.E).max() < EXACT


def test_planar_3d_input_equals_2d():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 100, (30, 2))
    tri = delaunay_triangles(pts)
    A = np.array([[1.2, 0.3], [-0.1, 0.8]])
    cur = np.stack([pts, pts @ A.T + 5, (pts**1.1)])
    f2 = compute_strain(pts, cur, tri)
    z0 = 7.5
    pad = lambda p: np.concatenate([p, np.full((*p.shape[:-1], 1), z0)], axis=-1)  # noqa: E731
    f3 = compute_strain(pad(pts), pad(cur), tri)
    np.testing.assert_allclose(f3.E, f2.E, atol=EXACT)
    np.testing.assert_allclose(f3.nodal_E, f2.nodal_E, atol=EXACT)


def test_3d_membrane_stretch_in_a_tilted_plane():
    """A sheet in an arbitrary plane, stretched along material X by 1.3: Exx = 0.345."""
    rng = np.random.default_rng(4)
    Q = random_rotation3(rng)
    pts2 = rng.uniform(0, 10, (25, 2))
    tri = delaunay_triangles(pts2)
    ref = np.column_stack([pts2, np.zeros(25)]) @ Q.T
    cur = np.column_stack([pts2 * [1.3, 1.0], np.zeros(25)]) @ Q.T
    f = compute_strain(ref, cur[None], tri, directions=np.eye(3)[:2] @ Q.T)
    np.testing.assert_allclose(f.E[0, :, 0, 0], 0.5 * (1.3**2 - 1), atol=EXACT)
    np.testing.assert_allclose(f.E[0, :, 1, 1], 0, atol=EXACT)
    np.testing.assert_allclose(f.E[0, :, 0, 1], 0, atol=EXACT)


def test_matches_multidic_dual_basis_formulation():
    """F = d1 (x) D^1 + d2 (x) D^2 + n (x) N with dual basis vectors (Solav et al. 2018)."""
    rng = np.random.default_rng(5)
    ref = rng.normal(size=(3, 3))
    cur = ref @ rng.normal(size=(3, 3)).T * 0.3 + ref
    tri = np.array([[0, 1, 2]])
    F = deformation_gradient(ref, cur, tri)[0]  # (3, 2) in the tangent basis
    basis, _ = reference_frames(ref, tri)
    D = np.stack([ref[1] - ref[0], ref[2] - ref[0]], axis=1)
    d = np.stack([cur[1] - cur[0], cur[2] - cur[0]], axis=1)
    N = np.cross(D[:, 0], D[:, 1])
    N /= np.linalg.norm(N)
    Dual = np.linalg.inv(np.column_stack([D, N]))  # rows: D^1, D^2, N
    n = np.cross(d[:, 0], d[:, 1])
    n /= np.linalg.norm(n)
    F_md = np.outer(d[:, 0], Dual[0]) + np.outer(d[:, 1], Dual[1]) + np.outer(n, Dual[2])
    # restricted to the reference tangent plane the two maps agree
    np.testing.assert_allclose(F_md @ basis[0], F, atol=EXACT)
    C_md = (F_md @ basis[0]).T @ (F_md @ basis[0])
    np.testing.assert_allclose(0.5 * (C_md - np.eye(2)), green_lagrange(F), atol=EXACT)


def test_euler_almansi_2d_closed_form():
    F = np.array([[1.3, 0.2], [-0.1, 0.9]])
    expected = 0.5 * (np.eye(2) - np.linalg.inv(F @ F.T))
    np.testing.assert_allclose(euler_almansi(F), expected, atol=EXACT)


def test_logarithmic_strain_of_stretch():
    F = np.diag([1.5, 0.7])
    np.testing.assert_allclose(logarithmic_strain(F), np.diag(np.log([1.5, 0.7])), atol=EXACT)
    R = rot2(0.4)
    np.testing.assert_allclose(logarithmic_strain(R @ F), np.diag(np.log([1.5, 0.7])), atol=EXACT)


def test_principal_strains_order_directions_and_nan():
    E = np.array([[[0.1, 0.0], [0.0, 0.3]], [[np.nan] * 2] * 2])
    values, vectors = principal_strains(E)
    np.testing.assert_allclose(values[0], [0.3, 0.1])
    np.testing.assert_allclose(np.abs(vectors[0][:, 0]), [0, 1], atol=EXACT)
    assert np.isnan(values[1]).all()


def test_directional_components_rotate_the_tensor():
    E = np.array([[[0.2, 0.05], [0.05, -0.1]]])
    basis = np.eye(2)[None]
    a = 0.3
    dirs = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
    R = dirs.T
    np.testing.assert_allclose(
        directional_components(E, basis, dirs)[0], R.T @ E[0] @ R, atol=EXACT
    )
    np.testing.assert_allclose(directional_components(E, basis), E, atol=EXACT)
    with pytest.raises(ValueError, match="parallel"):
        directional_components(E, basis, [[1, 0], [2, 0]])


def test_degenerate_reference_triangle_is_refused():
    ref = np.array([[0.0, 0], [1, 0], [2, 0]])
    with pytest.raises(ValueError, match="degenerate"):
        deformation_gradient(ref, ref, np.array([[0, 1, 2]]))


affine_maps = arrays(np.float64, (2, 2), elements=st.floats(-0.6, 0.6))


@settings(max_examples=60, deadline=None)
@given(
    grad_u=affine_maps,
    shift=arrays(np.float64, 2, elements=st.floats(-50, 50)),
    angle=st.floats(-np.pi, np.pi),
)
def test_property_affine_maps_give_their_analytic_strain(grad_u, shift, angle):
    F_true = np.eye(2) + grad_u
    if np.linalg.det(F_true) < 0.2:  # keep orientation-preserving, non-degenerate maps
        return
    x = GRID @ F_true.T + shift
    E_true = 0.5 * (F_true.T @ F_true - np.eye(2))
    field = compute_strain(GRID, x[None], TRI)
    np.testing.assert_allclose(
        field.nodal_E[0], np.broadcast_to(E_true, (len(GRID), 2, 2)), atol=1e-9
    )
    # a superposed rigid rotation leaves E unchanged and J = det F
    x_rot = x @ rot2(angle).T
    f_rot = compute_strain(GRID, x_rot[None], TRI)
    np.testing.assert_allclose(f_rot.E, field.E, atol=1e-9)
    np.testing.assert_allclose(area_ratio(f_rot.F), np.linalg.det(F_true), rtol=1e-9)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (3,), elements=st.floats(-2, 2)))
def test_property_principal_pairs_solve_the_eigen_problem(abd):
    a, b, d = abd
    E = np.array([[a, b], [b, d]])
    values, vectors = principal_strains(E)
    assert values[0] >= values[1]
    for k in range(2):
        np.testing.assert_allclose(E @ vectors[:, k], values[k] * vectors[:, k], atol=1e-12)
    np.testing.assert_allclose(vectors.T @ vectors, np.eye(2), atol=1e-12)
    assert -np.pi / 2 < np.arctan2(vectors[1, 0], vectors[0, 0]) <= np.pi / 2 + 1e-12


def test_alternative_strain_measures_keep_lost_triangles_nan():
    F = np.array([[[1.3, 0.2], [-0.1, 0.9]], [[np.nan, 0], [0, 1]]])
    for measure in (euler_almansi, logarithmic_strain):
        out = measure(F)
        assert np.isnan(out[1]).all()
        assert np.isfinite(out[0]).all()
    F3 = np.full((2, 3, 2), np.nan)
    F3[0] = [[1, 0], [0, 1], [0, 0]]
    assert np.isnan(euler_almansi(F3)[1]).all() and np.allclose(euler_almansi(F3)[0], 0)

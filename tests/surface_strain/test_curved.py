"""Membrane strain on curved 3D surfaces against analytic answers.

Discretization bounds used below (derived in the test docstrings):

* cylinder, uniform inflation ``R0 -> R1`` and axial stretch ``lz``: the map is
  linear, ``x = diag(k, k, lz) X`` with ``k = R1 / R0``, so each constant-strain
  triangle (CST) sees it exactly; in the (axial, circumferential) frame the
  hoop strain is exact and the axial one is off by ``(k^2 - lz^2) / 2 * n_z^2``
  with ``n_z`` the axial component of the chordal triangle's normal, and
  ``|n_z| <= R0^2 |a b c| / (4 A)`` (``a, b, c`` the angular spans of its edges,
  ``A`` its area);
* any smooth map ``phi`` of a flat reference with second derivatives bounded
  by ``M2``: on a triangle with centroid ``c``, ``|F_cst - grad phi(c)| <= dF =
  M2 rho sqrt(|D1|^2 + |D2|^2) / s_min(G)`` and ``|E_cst - E(c)| <= |F(c)| dF +
  dF^2 / 2`` (Frobenius norms; ``rho`` the largest centroid-vertex distance).
"""

import numpy as np
import pytest

from surface_strain import (
    area_ratio,
    best_fit_cylinder,
    best_fit_sphere,
    compute_strain,
    cylindrical_directions,
    delaunay_triangles,
    edge_lengths,
    element_principal_directions,
    element_scalars,
    folded_triangles,
    grid_triangles,
    material_frame,
    nodal_axes,
    nodal_principal_directions,
    nodal_scalars,
    reference_frames,
    triangle_areas,
    triangle_normals,
)
from tests.tolerances import ROUNDOFF

Z_AXIS = ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])


def random_rotation3(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def tube_mesh(n_theta, n_z, *, stagger=0.0):
    """Closed tube grid: angles (n_z * n_theta,), axial positions, triangles.

    Row ``j`` of the grid is shifted by ``stagger`` of an angular step on odd
    rows; the seam is closed by wrapping the last column onto the first.
    """
    j, i = np.mgrid[0:n_z, 0:n_theta]
    theta = ((i + stagger * (j % 2)) * 2 * np.pi / n_theta).ravel()
    z = (j / (n_z - 1)).ravel()
    tri = grid_triangles(n_z, n_theta + 1)
    row, col = tri // (n_theta + 1), tri % (n_theta + 1)
    return theta, z, row * n_theta + col % n_theta


def on_cylinder(theta, z, radius, length):
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta), length * z])


def assert_orthonormal(a, b, atol=ROUNDOFF):
    ok = np.all(np.isfinite(a), axis=-1)
    np.testing.assert_allclose(np.linalg.norm(a[ok], axis=-1), 1, atol=atol)
    np.testing.assert_allclose(np.linalg.norm(b[ok], axis=-1), 1, atol=atol)
    np.testing.assert_allclose(np.sum(a[ok] * b[ok], axis=-1), 0, atol=atol)


def cst_bound(ref2, triangles, M2, F_norm):
    """Per-triangle bound on ``|E_cst - E(centroid)|`` for a map with ``|D^2 phi| <= M2``."""
    q = ref2[triangles]
    rho = np.linalg.norm(q - q.mean(axis=1, keepdims=True), axis=-1).max(axis=1)
    G = np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]], axis=-1)
    s_min = np.linalg.svd(G, compute_uv=False)[:, -1]
    dF = M2 * rho * np.sqrt(np.sum(G**2, axis=(1, 2))) / s_min
    return F_norm * dF + 0.5 * dF**2


def hessian_norm(phi, samples, eps=1e-4):
    """Largest Frobenius norm of the second derivatives of ``phi: (K, 2) -> (K, 3)``."""
    H = np.zeros((len(samples), 3, 2, 2))
    for a in range(2):
        for b in range(2):
            ea, eb = np.eye(2)[a] * eps, np.eye(2)[b] * eps
            H[..., a, b] = (
                phi(samples + ea + eb)
                - phi(samples + ea - eb)
                - phi(samples - ea + eb)
                + phi(samples - ea - eb)
            ) / (4 * eps**2)
    return np.sqrt(np.sum(H**2, axis=(1, 2, 3))).max()


# --- rigid motion ---------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(3))
def test_rigid_motion_of_a_curved_sheet(seed):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1, 1, (80, 2))
    ref = np.column_stack([xy, 0.5 * np.sin(2 * xy[:, 0]) * np.cos(1.5 * xy[:, 1])])
    tri = delaunay_triangles(ref)
    Q = [random_rotation3(rng) for _ in range(3)]
    moved = np.stack([ref @ q.T + rng.normal(size=3) for q in Q])
    field = compute_strain(ref, moved, tri)
    meshed = np.isin(np.arange(len(ref)), tri)  # overlong-edge removal may leave a node out
    assert np.abs(field.E).max() < ROUNDOFF
    assert np.abs(field.nodal_E[:, meshed]).max() < ROUNDOFF
    np.testing.assert_allclose(area_ratio(field.F), 1, atol=ROUNDOFF)
    element = element_principal_directions(field)
    node = nodal_principal_directions(field)
    assert all(np.isfinite(v).all() for v in element)
    assert all(np.isfinite(v[:, meshed]).all() for v in node)
    for pd in (element, node):
        assert_orthonormal(pd.dir1_ref, pd.dir2_ref)
        assert_orthonormal(pd.dir1_cur, pd.dir2_cur)
        # a rigid motion carries the directions along
        for t, q in enumerate(Q):
            np.testing.assert_allclose(pd.dir1_cur[t], pd.dir1_ref[t] @ q.T, atol=1e-9)
            np.testing.assert_allclose(pd.dir2_cur[t], pd.dir2_ref[t] @ q.T, atol=1e-9)
    # the isotropic option marks the (meaningless) directions of zero strain
    assert np.isnan(element_principal_directions(field, isotropic="nan").dir1_ref).all()


# --- inflated and stretched cylinder --------------------------------------------------

R0, R1, LENGTH, LAMBDA_Z = 2.0, 2.6, 5.0, 1.15
E_HOOP = 0.5 * ((R1 / R0) ** 2 - 1)
E_AXIAL = 0.5 * (LAMBDA_Z**2 - 1)


def inflated_tube(n_theta, n_z, *, stagger=0.0, **kwargs):
    theta, z, tri = tube_mesh(n_theta, n_z, stagger=stagger)
    ref = on_cylinder(theta, z, R0, LENGTH)
    cur = on_cylinder(theta, z, R1, LAMBDA_Z * LENGTH)
    field = compute_strain(ref, np.stack([ref, cur]), tri, **kwargs)
    return field, theta, ref, tri


@pytest.mark.parametrize("n", [1, 2])
def test_cylinder_on_its_grid_is_exact(n):
    """Every grid triangle has an axial and a hoop edge, so its plane holds the
    axial direction (n_z = 0) and the chord, stretched exactly by R1/R0."""
    field, *_ = inflated_tube(12 * n, 5 * n + 1, directions="cylindrical", axis=Z_AXIS)
    for E in (field.E[1], field.nodal_E[1]):
        np.testing.assert_allclose(E[:, 0, 0], E_AXIAL, atol=ROUNDOFF)
        np.testing.assert_allclose(E[:, 1, 1], E_HOOP, atol=ROUNDOFF)
        np.testing.assert_allclose(E[:, 0, 1], 0, atol=ROUNDOFF)
    np.testing.assert_allclose(field.E[0], 0, atol=ROUNDOFF)
    J = element_scalars(field)["J"][1]
    np.testing.assert_allclose(J, (R1 / R0) * LAMBDA_Z, rtol=ROUNDOFF)
    # E1 is the hoop strain here; its direction is the chord, tangent to the hoop
    node = nodal_principal_directions(field)
    hoop = cylindrical_directions(field.reference, axis=Z_AXIS)[:, 1]
    np.testing.assert_allclose(np.abs(np.sum(node.dir1_ref[1] * hoop, axis=1)), 1, atol=ROUNDOFF)
    np.testing.assert_allclose(np.abs(node.dir2_ref[1, :, 2]), 1, atol=ROUNDOFF)
    np.testing.assert_allclose(nodal_scalars(field)["max_shear"][1], 0.5 * (E_HOOP - E_AXIAL))


def test_cylinder_on_a_staggered_mesh_error_is_the_chordal_formula():
    """Without axial edges the chordal planes tilt: the hoop strain stays exact,
    the axial strain is off by exactly (k^2 - lz^2)/2 n_z^2, bounded through
    |n_z| <= R0^2 |a b c| / (4 A) and shrinking as h^2 (measured: 7.05e-3 and
    1.89e-3 at 12 x 6 and 24 x 11 nodes)."""
    k = R1 / R0
    errors, bounds = [], []
    for n in (1, 2):
        field, theta, ref, tri = inflated_tube(
            12 * n, 5 * n + 1, stagger=0.5, directions="cylindrical", axis=Z_AXIS
        )
        n_z = triangle_normals(ref, tri)[:, 2]
        spans = np.angle(np.exp(1j * (theta[tri] - theta[tri[:, [1, 2, 0]]])))
        bound = (
            abs(k**2 - LAMBDA_Z**2)
            / 2
            * (R0**2 * np.prod(np.abs(spans), axis=1) / (4 * triangle_areas(ref, tri))) ** 2
        )
        error = field.E[1, :, 0, 0] - E_AXIAL
        np.testing.assert_allclose(error, 0.5 * (k**2 - LAMBDA_Z**2) * n_z**2, atol=ROUNDOFF)
        assert np.all(np.abs(error) <= bound + ROUNDOFF)
        np.testing.assert_allclose(field.E[1, :, 1, 1], E_HOOP, atol=ROUNDOFF)
        np.testing.assert_allclose(field.E[1, :, 0, 1], 0, atol=ROUNDOFF)
        nodal_error = np.abs(field.nodal_E[1, :, 0, 0] - E_AXIAL).max()
        assert nodal_error <= bound.max()
        errors.append(np.abs(error).max())
        bounds.append(bound.max())
    assert errors[1] < errors[0] / 3.5  # second order: 3.72 measured
    assert bounds[1] < bounds[0] / 3.5


def test_cylinder_direction_fields_agree():
    """'cylindrical', per-triangle and per-node vectors give the same frame."""
    named, *_ = inflated_tube(16, 7, directions="cylindrical", axis=Z_AXIS)
    ref, tri = named.reference, named.triangles
    per_triangle = cylindrical_directions(ref[tri].mean(axis=1), axis=Z_AXIS)
    per_node = cylindrical_directions(ref, axis=Z_AXIS)
    for directions in (per_triangle, per_node):
        f = compute_strain(ref, named.points, tri, directions=directions)
        np.testing.assert_allclose(f.E, named.E, atol=ROUNDOFF)
        np.testing.assert_allclose(f.nodal_E, named.nodal_E, atol=ROUNDOFF)
    assert named.meta == {"directions": "cylindrical", "axis": [[0, 0, 0], [0, 0, 1]]}
    np.testing.assert_allclose(
        named.frame[:, :, 0], np.broadcast_to([0, 0, 1], (len(tri), 3)), atol=ROUNDOFF
    )


def test_direction_normal_to_the_surface_is_refused():
    theta, z, tri = tube_mesh(12, 4)
    ref = on_cylinder(theta, z, R0, LENGTH)
    with pytest.raises(ValueError, match=r"first direction is normal .* first is triangle"):
        # the normal of one triangle (the radial direction at its mid-angle)
        normal = triangle_normals(ref, tri)[5]
        compute_strain(ref, ref[None], tri, directions=[normal, [0, 0, 1]])
    with pytest.raises(ValueError, match="the default global X and Y"):
        compute_strain(ref, ref[None], tri)
    flat = np.column_stack([ref[:, :2], np.zeros(len(ref))])[:3]
    with pytest.raises(ValueError, match="normal"):
        compute_strain(flat, flat[None], np.array([[0, 1, 2]]), directions=[[0, 0, 1.0], [1, 0, 0]])
    with pytest.raises(ValueError, match="parallel"):
        material_frame(reference_frames(flat, np.array([[0, 1, 2]]))[0], [[1, 0, 0], [2, 0, 0]])


def test_direction_options_are_checked():
    theta, z, tri = tube_mesh(12, 4)
    ref = on_cylinder(theta, z, R0, LENGTH)
    pts = ref[None]
    with pytest.raises(ValueError, match="axis"):
        compute_strain(ref, pts, tri, directions="cylindrical")
    with pytest.raises(ValueError, match="one of"):
        compute_strain(ref, pts, tri, directions="conical", axis=Z_AXIS)
    with pytest.raises(ValueError, match="axis"):
        compute_strain(ref, pts, tri, directions="cylindrical", axis=([0, 0, 0], [0, 0, 0]))
    with pytest.raises(ValueError, match="directions_at"):
        compute_strain(ref, pts, tri, directions_at="corners")
    # a prism (a tube of 3 x 2 nodes) has as many nodes as triangles: say which
    theta, z, tri6 = tube_mesh(3, 2)
    prism = on_cylinder(theta, z, 1.0, 1.0)
    d6 = cylindrical_directions(prism, axis=Z_AXIS)
    assert len(prism) == len(tri6) == 6
    with pytest.raises(ValueError, match="directions_at"):
        compute_strain(prism, prism[None], tri6, directions=d6)
    at_nodes = compute_strain(prism, prism[None], tri6, directions=d6, directions_at="nodes")
    at_triangles = compute_strain(
        prism, prism[None], tri6, directions=d6[tri6].mean(axis=1), directions_at="triangles"
    )
    np.testing.assert_allclose(at_nodes.frame, at_triangles.frame, atol=ROUNDOFF)


# --- inflating spherical cap ----------------------------------------------------------

CAP_R, CAP_LAMBDA = 1.5, 1.1  # sphere radius, meridional stretch; reference disc radius 1


def disc_points(h):
    """Hexagonal lattice of spacing h inside the unit disc plus a ring on its rim."""
    n = int(np.ceil(1.2 / h))
    j, i = np.mgrid[-n : n + 1, -n : n + 1]
    p = np.column_stack([((i + 0.5 * j) * h).ravel(), (j * h * np.sqrt(3) / 2).ravel()])
    p = p[np.linalg.norm(p, axis=1) <= 1 - 0.5 * h]
    a = np.arange(round(2 * np.pi / h)) * 2 * np.pi / round(2 * np.pi / h)
    return np.vstack([p, np.column_stack([np.cos(a), np.sin(a)])])


def cap_map(p2):
    """Meridional arc length s = lambda rho on a sphere of radius R (pole at the origin)."""
    rho = np.linalg.norm(p2, axis=1)
    phi = np.arctan2(p2[:, 1], p2[:, 0])
    s = CAP_LAMBDA * rho
    r = CAP_R * np.sin(s / CAP_R)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), CAP_R * (np.cos(s / CAP_R) - 1)])


def cap_strain(rho):
    """Exact (E_meridional, E_circumferential) at reference radius rho."""
    safe = np.where(rho > 0, rho, 1.0)
    stretch = np.where(rho > 0, CAP_R * np.sin(CAP_LAMBDA * safe / CAP_R) / safe, CAP_LAMBDA)
    return 0.5 * (CAP_LAMBDA**2 - 1) + 0 * rho, 0.5 * (stretch**2 - 1)


def test_inflating_spherical_cap():
    """A flat disc mapped onto a sphere (meridional stretch lambda, circumferential
    R sin(lambda rho / R) / rho), in the spherical (meridional, circumferential)
    frame.  Element errors stay below the CST bound (M2 from the map's second
    derivatives); nodal errors stay below that bound plus the change of the
    exact field between centroid and node.  Measured at h = 0.1 and 0.05: nodal
    max 9.6e-3 -> 5.1e-3 (first order, set by the rim), interior nodes (2 h from
    the rim) 1.08e-3 -> 2.7e-4 (second order on the uniform lattice)."""
    rng = np.random.default_rng(0)
    r, a = np.sqrt(rng.uniform(0, 1, 4000)), rng.uniform(0, 2 * np.pi, 4000)
    M2 = 1.05 * hessian_norm(cap_map, np.column_stack([r * np.cos(a), r * np.sin(a)]))
    results = []
    for h in (0.1, 0.05):
        p2 = disc_points(h)
        ref = np.column_stack([p2, np.zeros(len(p2))])
        tri = delaunay_triangles(ref)
        frames = np.stack([ref, cap_map(p2)])
        field = compute_strain(ref, frames, tri, directions="spherical", axis=Z_AXIS)
        np.testing.assert_allclose(field.E[0], 0, atol=ROUNDOFF)
        # elements against the exact strain at their centroid
        rho_c = np.linalg.norm(p2[tri].mean(axis=1), axis=1)
        e_m, e_c = cap_strain(rho_c)
        E = field.E[1]
        err_elem = np.sqrt((E[:, 0, 0] - e_m) ** 2 + (E[:, 1, 1] - e_c) ** 2 + 2 * E[:, 0, 1] ** 2)
        bound_elem = cst_bound(p2, tri, M2, F_norm=CAP_LAMBDA)
        assert np.all(err_elem <= bound_elem)
        # nodes against the exact strain at the node
        rho = np.linalg.norm(p2, axis=1)
        n_m, n_c = cap_strain(rho)
        N = field.nodal_E[1]
        err_node = np.sqrt((N[:, 0, 0] - n_m) ** 2 + (N[:, 1, 1] - n_c) ** 2 + 2 * N[:, 0, 1] ** 2)
        shift = np.abs(e_c[:, None] - n_c[tri])  # exact field: centroid vs its nodes
        per_corner = np.broadcast_to((bound_elem[:, None] + shift), tri.shape)
        bound_node = np.zeros(len(p2))
        np.maximum.at(bound_node, tri.ravel(), per_corner.ravel())
        assert np.all(err_node <= bound_node)
        interior = rho < 1 - 2 * h
        results.append((err_node.max(), err_node[interior].max(), np.median(bound_elem)))
    (coarse, coarse_in, coarse_b), (fine, fine_in, fine_b) = results
    assert fine < coarse / 1.7  # first order overall (1.89 measured)
    assert fine_in < coarse_in / 3.5  # second order inside (4.0 measured)
    assert fine_b < coarse_b / 1.8  # the bound shrinks as h
    assert coarse < 0.012 and coarse_in < 1.2e-3


def test_polar_frame_in_2d_equals_the_spherical_frame_on_a_flat_disc():
    p2 = disc_points(0.25)
    cur2 = p2 * (1 + 0.2 * np.linalg.norm(p2, axis=1))[:, None]
    tri = delaunay_triangles(p2)
    f2 = compute_strain(p2, cur2[None], tri, directions="polar", axis=(0.0, 0.0))
    pad = lambda p: np.concatenate([p, np.zeros((*p.shape[:-1], 1))], axis=-1)  # noqa: E731
    f3 = compute_strain(pad(p2), pad(cur2)[None], tri, directions="spherical", axis=Z_AXIS)
    np.testing.assert_allclose(f3.E, f2.E, atol=ROUNDOFF)
    # radial stretch 1 + 0.4 rho, hoop 1 + 0.2 rho: E_rr > E_tt, dir1 is radial
    d1 = element_principal_directions(f3).dir1_ref[0]
    radial = pad(p2)[tri].mean(axis=1)
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.median(np.abs(np.sum(d1 * radial, axis=1))) > 0.99
    with pytest.raises(ValueError, match="3D"):
        compute_strain(p2, cur2[None], tri, directions="cylindrical", axis=(0.0, 0.0))


# --- isometric bending ----------------------------------------------------------------


def bend(ref, radius):
    """Roll the sheet (s, 0, z) onto a cylinder of the given radius without stretching."""
    s, z = ref[:, 0], ref[:, 2]
    return np.column_stack([radius * np.sin(s / radius), radius * (1 - np.cos(s / radius)), z])


def test_bending_a_sheet_into_a_cylinder_on_its_grid():
    """Grid triangles have an s edge (now a chord) and a z edge: E_ss is exactly
    (sinc^2(h / 2R) - 1) / 2 >= -h^2 / (12 R^2), the rest 0.  Measured:
    -1.66e-3 and -4.17e-4 at h = 0.2 and 0.1 (R = 1)."""
    radius, width = 1.0, 3.0
    errors = []
    for n in (15, 30):
        s, z = np.meshgrid(np.linspace(0, width, n + 1), np.linspace(0, 1, 6))
        ref = np.column_stack([s.ravel(), np.zeros(s.size), z.ravel()])
        tri = grid_triangles(6, n + 1)
        field = compute_strain(
            ref, bend(ref, radius)[None], tri, directions=[[1.0, 0, 0], [0, 0, 1]]
        )
        h = width / n
        half = h / (2 * radius)
        exact = 0.5 * ((np.sin(half) / half) ** 2 - 1)
        for E in (field.E[0], field.nodal_E[0]):
            np.testing.assert_allclose(E[:, 0, 0], exact, atol=ROUNDOFF)
            np.testing.assert_allclose(E[:, 1, 1], 0, atol=ROUNDOFF)
            np.testing.assert_allclose(E[:, 0, 1], 0, atol=ROUNDOFF)
        assert abs(exact) <= h**2 / (12 * radius**2)
        errors.append(abs(exact))
    assert errors[1] == pytest.approx(errors[0] / 4, rel=0.01)


def test_bending_a_scattered_sheet_stays_within_the_cst_bound():
    """A jittered point set bent isometrically (|D^2 phi| = 1/R): the membrane
    strain is the discretization error only, below the CST bound, and it
    shrinks as h^2 (measured max |E|: 3.0e-3 -> 8.7e-4 per triangle,
    2.4e-3 -> 6.9e-4 per node, at h = 0.2 and 0.1 with R = 1)."""
    radius = 1.0
    rng = np.random.default_rng(3)
    elem, node = [], []
    for h in (0.2, 0.1):
        s, z = np.meshgrid(np.arange(0, 3 + 1e-9, h), np.arange(0, 1 + 1e-9, h))
        pts = np.column_stack([s.ravel(), z.ravel()])
        pts = pts + rng.uniform(-0.2, 0.2, pts.shape) * h
        ref = np.column_stack([pts[:, 0], np.zeros(len(pts)), pts[:, 1]])
        tri = delaunay_triangles(ref, min_quality=0.3)
        field = compute_strain(ref, bend(ref, radius)[None], tri, directions=[[1, 0, 0], [0, 0, 1]])
        err = np.sqrt(np.sum(field.E[0] ** 2, axis=(1, 2)))
        assert np.all(err <= cst_bound(pts, tri, 1 / radius, F_norm=1.0))
        elem.append(err.max())
        node.append(np.sqrt(np.sum(field.nodal_E[0] ** 2, axis=(1, 2))).max())
    assert elem[1] < elem[0] / 3 and node[1] < node[0] / 3
    assert elem[0] < 4e-3


# --- planar input in 3D ---------------------------------------------------------------


@pytest.mark.parametrize("tilted", [False, True])
def test_planar_3d_equals_2d(tilted):
    rng = np.random.default_rng(7)
    p2 = rng.uniform(0, 100, (40, 2))
    tri = delaunay_triangles(p2)
    A = np.array([[1.2, 0.3], [-0.1, 0.8]])
    cur2 = np.stack([p2, p2 @ A.T + 5, p2 + 3 * np.sin(p2 / 20)])
    Q = random_rotation3(rng) if tilted else np.eye(3)
    shift = rng.normal(size=3) * 10 if tilted else np.zeros(3)

    def lift(p):
        return np.concatenate([p, np.zeros((*p.shape[:-1], 1))], axis=-1) @ Q.T + shift

    f2 = compute_strain(p2, cur2, tri)
    f3 = compute_strain(lift(p2), lift(cur2), tri, directions=Q[:, :2].T)
    np.testing.assert_allclose(f3.E, f2.E, atol=ROUNDOFF)
    np.testing.assert_allclose(f3.nodal_E, f2.nodal_E, atol=ROUNDOFF)
    for s2, s3 in (
        (element_scalars(f2), element_scalars(f3)),
        (nodal_scalars(f2), nodal_scalars(f3)),
    ):
        for key in ("E1", "E2", "J", "max_shear", "Exx", "Eyy", "Exy"):
            np.testing.assert_allclose(s3[key], s2[key], atol=ROUNDOFF, err_msg=key)
    for d2, d3 in (  # frame 0 is isotropic (no strain): no direction to compare there
        (
            element_principal_directions(f2, isotropic="nan"),
            element_principal_directions(f3, isotropic="nan"),
        ),
        (
            nodal_principal_directions(f2, isotropic="nan"),
            nodal_principal_directions(f3, isotropic="nan"),
        ),
    ):
        for v2, v3 in zip(d2, d3, strict=True):
            ok = np.isfinite(v2).all(axis=-1)
            np.testing.assert_allclose(v3[ok], (lift(v2) - shift)[ok], atol=1e-9)


# --- principal directions -------------------------------------------------------------


def test_principal_directions_of_a_stretch_on_a_tilted_plane():
    """Stretch 1.4 along the in-plane direction u, then a rigid motion: dir1 is u
    in 3D (up to sign), dir1_cur = F dir1 / |F dir1| = Q_rigid u."""
    rng = np.random.default_rng(11)
    Q = random_rotation3(rng)
    Q_rigid = random_rotation3(rng)
    angle = np.radians(35)
    u2 = np.array([np.cos(angle), np.sin(angle)])
    F2 = np.eye(2) + 0.4 * np.outer(u2, u2)
    p2 = rng.uniform(-5, 5, (50, 2))
    tri = delaunay_triangles(p2)

    def lift(p):
        return np.column_stack([p, np.zeros(len(p))]) @ Q.T

    ref = lift(p2)
    cur = lift(p2 @ F2.T) @ Q_rigid.T + [1.0, -2.0, 0.5]
    field = compute_strain(ref, cur[None], tri)
    u = Q @ np.append(u2, 0)
    normal = Q[:, 2]
    for pd in (element_principal_directions(field), nodal_principal_directions(field)):
        d1 = pd.dir1_ref[0]
        np.testing.assert_allclose(np.abs(d1 @ u), 1, atol=1e-9)
        np.testing.assert_allclose(pd.dir1_cur[0], d1 @ Q_rigid.T, atol=1e-9)
        np.testing.assert_allclose(np.abs(pd.dir2_ref[0] @ normal), 0, atol=1e-9)
        assert_orthonormal(pd.dir1_ref, pd.dir2_ref, atol=1e-9)
        assert_orthonormal(pd.dir1_cur, pd.dir2_cur, atol=1e-9)
        # (dir1, dir2, n) right-handed
        n = np.cross(pd.dir1_ref[0], pd.dir2_ref[0])
        np.testing.assert_allclose(np.abs(n @ normal), 1, atol=1e-9)
    scalars = element_scalars(field)
    np.testing.assert_allclose(scalars["E1"], 0.5 * (1.4**2 - 1), atol=ROUNDOFF)
    np.testing.assert_allclose(scalars["E2"], 0, atol=ROUNDOFF)
    np.testing.assert_allclose(scalars["max_shear"], 0.25 * (1.4**2 - 1), atol=ROUNDOFF)
    np.testing.assert_allclose(scalars["J"], 1.4, atol=ROUNDOFF)


def test_nodal_axes_align_signs_before_averaging():
    tri = np.array([[0, 1, 2], [1, 3, 2]])
    axes = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    out = nodal_axes(axes, tri, 4, orient=np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(out, np.broadcast_to([0, 1, 0], (4, 3)))
    lost = nodal_axes(np.array([[np.nan] * 3, [1.0, 0, 0]]), tri, 4)
    assert np.isnan(lost[0]).all() and np.isfinite(lost[1:]).all()


# --- meshes ---------------------------------------------------------------------------


def test_overlong_edges_bridging_a_concave_outline_are_removed():
    g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2)
    notch = (g[:, 0] >= 3) & (g[:, 1] >= 3) & (g[:, 1] <= 6)  # C shape, opening to +x
    pts = g[~notch]
    pts3 = np.column_stack([pts, 0.05 * pts[:, 0] ** 2])  # and curved in 3D
    for p in (pts, pts3):
        kept = delaunay_triangles(p)
        everything = delaunay_triangles(p, max_edge_ratio=None)
        c_kept = pts[kept].mean(axis=1)
        c_all = pts[everything].mean(axis=1)
        in_notch = lambda c: (c[:, 0] > 3.2) & (c[:, 1] > 3.2) & (c[:, 1] < 5.8)  # noqa: E731
        assert in_notch(c_all).any()  # Delaunay fills the convex hull ...
        assert not in_notch(c_kept).any()  # ... the filter empties the notch
        lengths = edge_lengths(p, kept)
        assert lengths.max() <= 3 * np.median(lengths)
        assert np.unique(kept).size == len(p)  # no point is left out
    with pytest.raises(ValueError, match="max_edge_ratio"):
        delaunay_triangles(pts, max_edge_ratio=0.5)


def sphere_points(polar_max_deg, n=1500, radius=2.0, center=(0.5, -1.0, 3.0)):
    i = np.arange(n)
    z = 1 - 2 * (i + 0.5) / n
    a = i * np.pi * (3 - np.sqrt(5))  # Fibonacci sphere
    p = np.column_stack([np.sqrt(1 - z**2) * np.cos(a), np.sqrt(1 - z**2) * np.sin(a), z])
    return radius * p[np.degrees(np.arccos(p[:, 2])) <= polar_max_deg] + center


def test_a_cap_beyond_the_hemisphere_needs_the_sphere_projection():
    center, radius = np.array([0.5, -1.0, 3.0]), 2.0
    pts = sphere_points(120)
    with pytest.raises(ValueError, match=r"folds over its best-fit plane.*projection='sphere'"):
        delaunay_triangles(pts)
    c, r = best_fit_sphere(pts)
    np.testing.assert_allclose(c, center, atol=1e-9)
    assert r == pytest.approx(radius, rel=1e-9)
    tri = delaunay_triangles(pts, projection="sphere")
    normals = triangle_normals(pts, tri)
    assert np.all(np.sum(normals * (pts[tri].mean(axis=1) - center), axis=1) > 0)  # outward
    cap_area = 2 * np.pi * radius**2 * (1 - np.cos(np.radians(120)))
    assert triangle_areas(pts, tri).sum() == pytest.approx(cap_area, rel=0.03)
    # uniform inflation about the centre is linear: E = (k^2 - 1)/2 exactly everywhere
    cur = center + 1.2 * (pts - center)
    field = compute_strain(pts, cur[None], tri)
    np.testing.assert_allclose(
        field.E[0], np.broadcast_to(np.eye(2) * 0.22, field.E[0].shape), atol=ROUNDOFF
    )
    # a cap within the hemisphere is still fine in its plane
    assert len(delaunay_triangles(sphere_points(60)))


def test_an_arch_needs_the_cylinder_projection():
    theta, z = np.meshgrid(np.linspace(0, 1.5 * np.pi, 30), np.linspace(0, 3, 10))
    rot = np.array([[1, 0, 0], [0, 0.8, -0.6], [0, 0.6, 0.8]])
    pts = on_cylinder(theta.ravel(), z.ravel() / 3, 1.5, 3) @ rot.T + [1, 2, 3]
    with pytest.raises(ValueError, match="folds"):
        delaunay_triangles(pts)
    point, direction, radius = best_fit_cylinder(pts)
    assert radius == pytest.approx(1.5, rel=1e-9)
    np.testing.assert_allclose(np.abs(direction @ rot[:, 2]), 1, atol=1e-9)
    for axis in (None, (point, rot[:, 2])):
        tri = delaunay_triangles(pts, projection="cylinder", axis=axis)
        assert len(tri) == 2 * 29 * 9
        assert triangle_areas(pts, tri).sum() == pytest.approx(1.5 * 1.5 * np.pi * 3, rel=2e-3)
    # the same tube frame as the grid: hoop exact, axial within the chordal formula
    cur = on_cylinder(theta.ravel(), z.ravel() / 3, 1.5 * R1 / R0, 3 * LAMBDA_Z) @ rot.T
    field = compute_strain(pts, cur[None], tri, directions="cylindrical", axis=(point, direction))
    np.testing.assert_allclose(field.E[0, :, 1, 1], E_HOOP, atol=ROUNDOFF)
    n_z = triangle_normals(pts, tri) @ direction
    expected = E_AXIAL + 0.5 * ((R1 / R0) ** 2 - LAMBDA_Z**2) * n_z**2
    np.testing.assert_allclose(field.E[0, :, 0, 0], expected, atol=ROUNDOFF)


def test_folded_grid_triangles_are_found():
    """A grid tracked over an overhang: its consistently oriented triangles flip.

    The sheet is a graph over z = 0 except where x(s) = s - b sin(ks) runs
    backwards (b k > 1).  By symmetry its best-fit plane is exactly z = 0,
    with a wide gap to the other axes, and each grid cell projects onto that
    plane with signed area proportional to its chord x(s_i+1) - x(s_i): the
    folded triangles are known without a cross product.
    """
    k, c = np.pi, 0.3
    b = 1.4 / k
    s = np.linspace(-3, 3, 61)
    x = s - b * np.sin(k * s)
    ss, yy = np.meshgrid(s, np.linspace(0, 2, 5))
    pts = np.column_stack([np.tile(x, 5), yy.ravel(), c * np.cos(k * ss.ravel())])
    tri = grid_triangles(5, 61)
    chord = np.diff(x)[(tri % 61).min(axis=1)]
    overhang = chord < 0  # the smaller part (20 %)
    assert 0.1 < overhang.mean() < 0.4 and np.abs(chord).min() > 1e-3
    folded = folded_triangles(pts, tri, normal=[0.0, 0.0, 1.0])
    assert np.array_equal(folded, overhang) or np.array_equal(folded, ~overhang)
    np.testing.assert_array_equal(folded_triangles(pts, tri), overhang)


def test_folded_triangles_edge_on_to_the_plane_are_not_folded():
    """An arc swept along y lies in its best-fit plane's normal direction.

    Every triangle stands edge-on to the best-fit plane (the x-z plane), so
    which side each faces is round-off: none may count as folded, on any machine.
    """
    theta, z = np.meshgrid(np.linspace(-0.2, 1.3 * np.pi, 25), np.linspace(0, 1, 4))
    pts = np.column_stack([np.cos(theta.ravel()), z.ravel(), np.sin(theta.ravel())])
    tri = grid_triangles(4, 25)
    assert not folded_triangles(pts, tri).any()
    # in a plane the surface is a graph over (z = 0), the arc's overhang is found
    overhang = np.sin(theta.ravel()[tri].mean(axis=1)) < 0
    folded = folded_triangles(pts, tri, normal=[0.0, 0.0, 1.0])
    assert np.array_equal(folded, overhang) or np.array_equal(folded, ~overhang)


# --- lost points ----------------------------------------------------------------------


def test_lost_points_on_a_curved_mesh_stay_confined():
    theta, z, tri = tube_mesh(16, 7)
    ref = on_cylinder(theta, z, R0, LENGTH)
    cur = np.stack([ref, on_cylinder(theta, z, R1, LAMBDA_Z * LENGTH)])
    lost_nan, lost_flag = 40, 60
    cur[1, lost_nan] = np.nan  # lost as NaN ...
    visible = np.ones(cur.shape[:2], bool)
    visible[1, lost_flag] = False  # ... and flagged (its position stays finite)
    field = compute_strain(ref, cur, tri, visible=visible, directions="cylindrical", axis=Z_AXIS)
    touching = np.any(np.isin(tri, [lost_nan, lost_flag]), axis=1)
    assert np.isnan(field.E[1, touching]).all()
    assert np.isfinite(field.E[1, ~touching]).all()
    assert np.isfinite(field.E[0]).all()
    lost = np.zeros(len(ref), bool)
    lost[[lost_nan, lost_flag]] = True
    node_scalars = nodal_scalars(field)
    for key in ("Exx", "Eyy", "E1", "E2", "max_shear", "J"):
        assert np.isnan(node_scalars[key][1, lost]).all(), key
        assert np.isfinite(node_scalars[key][1, ~lost]).all(), key
    np.testing.assert_allclose(node_scalars["Eyy"][1, ~lost], E_HOOP, atol=ROUNDOFF)
    np.testing.assert_allclose(node_scalars["J"][1, ~lost], R1 / R0 * LAMBDA_Z, rtol=ROUNDOFF)
    for v in nodal_principal_directions(field):
        assert np.isnan(v[1, lost]).all()
        assert np.isfinite(v[1, ~lost]).all()
    for v in element_principal_directions(field):
        assert np.isnan(v[1, touching]).all()
        assert np.isfinite(v[1, ~touching]).all()


def test_a_lost_reference_point_is_refused_with_its_index():
    ref = on_cylinder(*tube_mesh(8, 3)[:2], R0, LENGTH)
    tri = tube_mesh(8, 3)[2]
    bad = ref.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="point 5"):
        compute_strain(bad, ref[None], tri)

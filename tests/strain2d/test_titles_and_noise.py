"""Figures say what the data show: endpoints named after the deformation, crosses beyond noise."""

import numpy as np
import pytest

from strain2d.figures import plot_principal_crosses, principal_noise_floor
from strain2d.pipeline import strain_from_tracks
from strain2d.report import endpoint_of
from strain2d.tracks import Tracks


def _grid(n=7, spacing=40.0):
    ax = np.arange(n) * spacing + 60.0
    xx, yy = np.meshgrid(ax, ax)
    return np.column_stack([xx.ravel(), yy.ravel()])


def _field(mapping, n_frames=12, ramp_until=None, noise=0.0, seed=0):
    """A field whose frames apply mapping(s) with s ramping 0..1 (held after ramp_until)."""
    g = _grid()
    rng = np.random.default_rng(seed)
    ramp_until = n_frames - 1 if ramp_until is None else ramp_until
    s = np.minimum(np.arange(n_frames) / ramp_until, 1.0)
    pos = np.stack([mapping(g, v) for v in s])
    pos[1:] += rng.normal(0, noise, pos[1:].shape)
    tracks = Tracks(pos, np.ones(pos.shape[:2], bool), np.ones(pos.shape[:2]))
    return strain_from_tracks(tracks, grid_shape=(7, 7))


def _scale_about_centre(fx, fy):
    def mapping(g, s):
        c = g.mean(axis=0)
        return c + (g - c) * [1 + s * (fx - 1), 1 + s * (fy - 1)]

    return mapping


@pytest.mark.parametrize(
    ("fx", "fy", "kind"),
    [(0.8, 0.85, "contraction"), (1.2, 1.1, "stretch"), (1.2, 0.9, "deformation")],
)
def test_the_endpoint_is_named_after_the_deformation(fx, fy, kind):
    field = _field(_scale_about_centre(fx, fy), ramp_until=6)
    ep = endpoint_of(field)
    assert ep["source"] == "detected" and ep["deformation"] == kind
    assert ep["label"] == f"{kind} endpoint"


def test_an_endpoint_not_reached_is_not_called_one():
    field = _field(_scale_about_centre(1.2, 1.2))  # still stretching at the last frame
    ep = endpoint_of(field)
    assert ep["source"].startswith("not reached")
    assert ep["label"] == "last frame (stretch endpoint not reached)"
    assert endpoint_of(field, frame=5)["label"] == "stretch endpoint (given)"
    still = _field(lambda g, s: g)
    assert endpoint_of(still)["label"] == "last frame (no deformation)"


@pytest.mark.parametrize("factor", [1.0, 1.5, 0.6])
def test_the_noise_floor_is_what_noise_alone_gives(factor):
    """On an isotropic field (still, stretched or contracted) with independent tracking noise,
    about 5 % of nodes exceed the 95th-percentile floor taken at that deformation."""
    from surface_strain import compute_strain, nodal_scalars

    exact = _field(_scale_about_centre(factor, factor), n_frames=2, ramp_until=1)
    floor = principal_noise_floor(exact, 0.1, frame=-1)
    assert floor > 0
    # linear in the noise but for Green-Lagrange's quadratic term
    assert principal_noise_floor(exact, 0.2) == pytest.approx(2 * floor, rel=5e-3)
    assert principal_noise_floor(exact, 0.0) == 0.0
    rng = np.random.default_rng(100)  # independent of the floor's own draws
    exceed = []
    for _ in range(20):
        cur = exact.points[-1] + rng.normal(0, 0.1, exact.points[-1].shape)
        node = nodal_scalars(compute_strain(exact.reference, cur[None], exact.triangles))
        exceed.append(np.mean(node["E1"][0] - node["E2"][0] > floor))
    assert 0.02 < np.mean(exceed) < 0.09
    # the floor follows the deformation: a stretch amplifies the noise, a contraction damps it
    still = principal_noise_floor(_field(lambda g, s: g, n_frames=2), 0.1)
    if factor != 1.0:
        assert (floor > 1.2 * still) == (factor > 1) and (floor < 0.8 * still) == (factor < 1)


def test_crosses_are_drawn_only_beyond_noise():
    iso = _field(_scale_about_centre(1.1, 1.1), noise=0.05, seed=3)
    uni = _field(_scale_about_centre(1.1, 1.0), noise=0.05, seed=3)
    image = np.zeros((400, 400))
    floor = principal_noise_floor(iso, 0.05, frame=-1)
    drawn = {}
    for name, field in (("iso", iso), ("uni", uni)):
        fig = plot_principal_crosses(image, field, -1, noise=floor)
        by_gid = {c.get_gid(): c for c in fig.axes[0].collections}
        drawn[name] = len(by_gid["E1"].get_segments())
        circles = len(by_gid["isotropic"].get_offsets()) if "isotropic" in by_gid else 0
        assert drawn[name] + circles == 49
    # the floor is noise's 95th percentile: a few isotropic nodes still pass it by chance
    assert drawn["iso"] <= 8 and drawn["uni"] == 49
    # without a noise floor, noise alone draws directions on the isotropic field
    fig = plot_principal_crosses(image, iso, -1)
    assert len({c.get_gid(): c for c in fig.axes[0].collections}["E1"].get_segments()) == 49


def test_run_quality_counts_lost_points_and_the_area_they_take():
    from strain2d.figures import plot_run_quality, run_quality

    g = _grid()
    pos = np.stack([g, g * 1.01, g * 1.02])
    vis = np.ones((3, 49), bool)
    vis[2, 0] = False  # a corner: its one triangle of the grid's 72 loses its strain
    quality = np.ones((3, 49))
    quality[1] = np.linspace(0.5, 1.0, 49)
    tracks = Tracks(pos, vis, quality)
    field = strain_from_tracks(tracks, grid_shape=(7, 7))
    q = run_quality(tracks, field)
    assert q["visible_pct"] == [100.0, 100.0, pytest.approx(100 * 48 / 49)]
    lost_area = field.element_valid[2].size - field.element_valid[2].sum()
    assert lost_area in (1, 2)  # the corner node touches one or two triangles
    assert q["coverage_pct"][2] == pytest.approx(100 * (72 - lost_area) / 72)
    assert q["quality_median"][1] == pytest.approx(0.75)
    assert q["quality_p5"][1] == pytest.approx(np.percentile(quality[1], 5))
    assert q["uncertainty_median_px"] is None
    fig = plot_run_quality(q, [0.0, 0.5, 1.0], time_unit="s", tracker="dic")
    assert fig.axes[1].get_xlabel() == "time (s)" and "ZNCC" in fig.axes[1].get_ylabel()

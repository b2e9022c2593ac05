import numpy as np
import pytest
from matplotlib.contour import ContourSet
from matplotlib.figure import Figure
from matplotlib.image import imread

from strain2d.figures import (
    plot_strain_maps,
    plot_strain_maps_at,
    plot_tracked_grid,
    save_figure,
    strain_limits,
    strain_maps_figure,
)
from strain2d.pipeline import strain_from_tracks
from strain2d.tracks import Tracks
from surface_strain import compute_strain, grid_triangles, nodal_scalars

H, W = 60, 80  # small frames keep the tests fast


def _grid(n=5):
    x, y = np.meshgrid(np.linspace(15, 65, n), np.linspace(12, 48, n))
    return np.column_stack([x.ravel(), y.ravel()])


def _field(T=4, ax=0.1, ay=0.2, noise=0.2, n=5, seed=0, visible=None):
    """A grid contracting about the frame centre, more along y than x, with noise."""
    rng = np.random.default_rng(seed)
    X = _grid(n)
    c = np.array([W / 2, H / 2])
    s = np.linspace(0, 1, T)[:, None, None]
    pts = c + (X - c) * (1 - s * [ax, ay]) + rng.normal(0, noise, (T, *X.shape)) * (s > 0)
    return compute_strain(X, pts, grid_triangles(n, n), visible=visible)


def _frames(T=4, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (H, W), dtype=np.uint8) for _ in range(T)]


def _assert_image(path, shape=None, min_colours=20):
    """The PNG is not blank: visible contrast and more than a few colours."""
    img = imread(path)
    if shape is not None:
        assert img.shape[:2] == shape
    rgb = img[..., :3]
    assert rgb.std() > 0.05
    assert len(np.unique(rgb.reshape(-1, 3), axis=0)) > min_colours
    return img


def test_figures_render_with_lost_points_and_uniform_fields(tmp_path):
    ref = np.stack(np.meshgrid(np.linspace(20, 80, 4), np.linspace(20, 80, 4)), -1).reshape(-1, 2)
    pos = np.stack([ref, 50 + (ref - 50) * 1.2])  # uniform field: constant contour values
    vis = np.ones((2, 16), bool)
    vis[1, 0] = False
    tracks = Tracks(pos, vis, np.ones((2, 16)))
    field = strain_from_tracks(tracks)
    image = np.random.default_rng(0).uniform(0, 255, (100, 100))
    plot_tracked_grid(tmp_path / "grid.png", image, image, tracks, field.triangles)
    written = plot_strain_maps(tmp_path / "maps.png", image, field, 1)
    assert written == [tmp_path / "maps.png"]
    plot_strain_maps(tmp_path / "maps.svg", image, field, 1, components=("E1",))
    for name in ("grid.png", "maps.png"):
        img = imread(tmp_path / name)
        assert img.shape[0] > 300 and img.shape[1] > 600
        assert img[..., :3].std() > 0.05  # not blank
    assert (tmp_path / "maps.svg").read_text().startswith("<?xml")


# ------------------------------------------------------------------ save_figure


def _small_figure():
    fig = Figure(figsize=(3, 2), layout="constrained")
    ax = fig.add_subplot()
    ax.plot([0, 1, 2], [0, 1, 0], color="C0")
    ax.fill_between([0, 1, 2], [0, 0.5, 0], color="C1", alpha=0.5)
    ax.set_xlabel("frame")
    ax.set_ylabel("Green-Lagrange strain (-)")
    return fig


def test_save_figure_formats_suffixes_and_sizes(tmp_path):
    fig = _small_figure()
    written = save_figure(fig, tmp_path / "f.png", ("png", "svg", "pdf"), dpi=100)
    assert written == [tmp_path / "f.png", tmp_path / "f.svg", tmp_path / "f.pdf"]
    _assert_image(written[0], shape=(200, 300))  # figsize * dpi: nothing cropped
    assert written[0].read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    svg = written[1].read_text()
    assert svg.startswith("<?xml") and "<svg" in svg
    assert written[2].read_bytes().startswith(b"%PDF-")
    # no suffix -> PNG; a suffix alone picks the format; an unknown suffix is part of the name
    assert save_figure(fig, tmp_path / "g") == [tmp_path / "g.png"]
    assert save_figure(fig, tmp_path / "h.svg") == [tmp_path / "h.svg"]
    assert save_figure(fig, tmp_path / "run.v2", "pdf") == [tmp_path / "run.v2.pdf"]
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    # no creation dates: the same figure gives the same file on another day
    assert "<dc:date>" not in svg and b"/CreationDate" not in written[2].read_bytes()
    with pytest.raises(ValueError, match="unknown figure format"):
        save_figure(fig, tmp_path / "x", ("png", "docx"))
    with pytest.raises(ValueError, match="formats is empty"):
        save_figure(fig, tmp_path / "x", ())


# ------------------------------------------------------------------ colour limits


def test_strain_limits_cover_all_frames_and_ignore_nan_and_spikes():
    field = _field(T=5, noise=0.0)
    node = nodal_scalars(field)
    full = strain_limits(field, ("Exx", "Eyy"), percentile=0)
    for comp in ("Exx", "Eyy"):
        assert full[comp] == pytest.approx((np.nanmin(node[comp]), np.nanmax(node[comp])))
    assert full["Eyy"][0] == pytest.approx(0.5 * ((1 - 0.2) ** 2 - 1))  # the last frame
    assert full["Eyy"][1] == pytest.approx(0.0, abs=1e-12)  # the reference frame
    # given frames only
    mid = strain_limits(field, ("Eyy",), frames=[2], percentile=0, min_span=0)
    assert mid["Eyy"] == pytest.approx((0.5 * (0.9**2 - 1),) * 2)
    # a uniform field is widened to min_span about its value
    wide = strain_limits(field, ("Eyy",), frames=[-1], min_span=0.01)
    assert wide["Eyy"][1] - wide["Eyy"][0] == pytest.approx(0.01)
    sym = strain_limits(field, ("Eyy",), symmetric=True, percentile=0)
    assert sym["Eyy"][0] == pytest.approx(-sym["Eyy"][1]) == pytest.approx(full["Eyy"][0])
    # lost nodes (NaN) are left out, a one-frame spike at one node is clipped
    visible = np.ones((5, 25), bool)
    visible[2:, 12] = False
    lost = _field(T=5, noise=0.0, visible=visible)
    exx = nodal_scalars(lost)["Exx"]
    assert np.isnan(exx).any()
    assert strain_limits(lost, ("Exx",), percentile=0)["Exx"] == pytest.approx(
        (np.nanmin(exx), np.nanmax(exx))
    )
    spiky = _field(T=40, noise=0.0)
    spiky.nodal_E[20, 12, 0, 0] = 5.0  # a tracking glitch on one frame
    spiky.nodal_E[21, 12, 0, 0] = np.nan
    robust = strain_limits(spiky, ("Exx",))
    assert robust["Exx"][1] < 0.05
    assert strain_limits(spiky, ("Exx",), percentile=0)["Exx"][1] == 5.0
    with pytest.raises(ValueError, match="unknown strain component"):
        strain_limits(field, ("Ezz",))
    with pytest.raises(ValueError, match="out of range"):
        strain_limits(field, frames=[5])


def test_maps_at_several_frames_share_one_scale_with_zero_white(tmp_path):
    field = _field(T=4)
    frames = _frames(4)
    limits = strain_limits(field, ("Exx", "Eyy", "Exy"))
    comps = ("Exx", "Eyy", "Exy")
    seen = []
    for k in (1, 3):
        fig = strain_maps_figure(frames[k], field, k, limits=limits)
        bars = fig.axes[len(comps) :]
        assert [b.get_ylabel() for b in bars] == [
            f"{lab} (Green-Lagrange strain (-))" for lab in ("$E_{xx}$", "$E_{yy}$", "$E_{xy}$")
        ]
        assert [ax.get_xlabel() for ax in fig.axes[: len(comps)]] == ["x (px)"] * 3
        seen.append([b.get_ylim() for b in bars])
        for ax, comp in zip(fig.axes, comps, strict=False):
            (cs,) = [c for c in ax.get_children() if isinstance(c, ContourSet)]
            assert cs.levels[0] == pytest.approx(limits[comp][0])
            assert cs.levels[-1] == pytest.approx(limits[comp][1])
            lo, hi = limits[comp]
            if lo < 0 < hi:  # zero is white
                assert np.all(np.asarray(cs.cmap(cs.norm(0.0)))[:3] > 0.93)
            # the stronger end is the saturated end of RdBu_r
            end = cs.cmap(cs.norm(lo if abs(lo) >= abs(hi) else hi))
            assert min(end[:3]) < 0.45
    assert np.array(seen[0]) == pytest.approx(np.array(seen[1]))
    assert np.array(seen[0]) == pytest.approx(np.array([limits[c] for c in comps]))

    images = {0: frames[0], 2: frames[2], 3: frames[3]}
    written = plot_strain_maps_at(
        tmp_path / "strain", images, field, [2, -1], components=["Eyy"], formats=("png", "svg")
    )
    assert sorted(written) == [2, 3]
    assert written[3] == [tmp_path / "strain_frame0003.png", tmp_path / "strain_frame0003.svg"]
    _assert_image(written[2][0])
    assert len(list(tmp_path.iterdir())) == 4
    everything = plot_strain_maps_at(tmp_path / "all", images, field, components=["Exx"], dpi=40)
    assert sorted(everything) == [0, 2, 3]
    with pytest.raises(ValueError, match="no image given for frame 1"):
        plot_strain_maps_at(tmp_path / "x", images, field, [1])

import os
import subprocess
import sys
import time

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.contour import ContourSet
from matplotlib.figure import Figure
from matplotlib.image import imread

from strain2d.errors import InputError
from strain2d.figures import (
    format_p,
    mean_strain_curves,
    plot_principal_crosses,
    plot_specimen_means,
    plot_strain_curves,
    plot_strain_maps,
    plot_strain_maps_at,
    plot_strain_violins,
    plot_study_curves,
    plot_study_violins,
    plot_tracked_grid,
    save_figure,
    strain_limits,
    strain_maps_figure,
    write_strain_animation,
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


def _zlib_level(png: bytes) -> int:
    """FLEVEL of a PNG's image data stream: 0 fastest, 1 fast, 2 default, 3 best."""
    at = 8
    while at < len(png):
        size = int.from_bytes(png[at : at + 4], "big")
        if png[at + 4 : at + 8] == b"IDAT":
            return png[at + 9] >> 6  # the zlib header: CMF, then FLG
        at += size + 12
    raise AssertionError("no image data")


def test_png_figures_are_compressed_quickly_and_losslessly(tmp_path):
    import io

    from PIL import Image

    (path,) = save_figure(_small_figure(), tmp_path / "f.png", dpi=100)
    assert _zlib_level(path.read_bytes()) == 0  # zlib's fastest level
    buffer = io.BytesIO()
    _small_figure().savefig(buffer, format="png", dpi=100)
    assert _zlib_level(buffer.getvalue()) == 2  # Pillow's default, which is slower
    assert (np.asarray(Image.open(path)) == np.asarray(Image.open(buffer))).all()


def test_png_figures_are_drawn_once_into_the_file_savefig_writes(tmp_path, monkeypatch):
    """A figure with a layout engine is drawn once for its PNG (savefig draws it twice, to
    lay it out, then to render it), into the same bytes."""
    import io

    import matplotlib

    field = _field(T=3)
    image = _frames(1)[0]
    expected = io.BytesIO()
    strain_maps_figure(image, field, 2).savefig(
        expected, format="png", dpi=80, pil_kwargs={"compress_level": 1}
    )
    draws = []
    plain = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda fig, r: draws.append(1) or plain(fig, r))
    (path,) = save_figure(strain_maps_figure(image, field, 2), tmp_path / "m.png", dpi=80)
    assert len(draws) == 1 and path.read_bytes() == expected.getvalue()
    # a savefig style of the user's: drawn by savefig, which applies it
    draws.clear()
    with matplotlib.rc_context({"savefig.facecolor": "yellow"}):
        save_figure(strain_maps_figure(image, field, 2), tmp_path / "y.png", dpi=80)
    assert len(draws) == 2 and imread(tmp_path / "y.png")[0, 0, :3].tolist() == [1, 1, 0]


def test_tight_png_figures_are_drawn_once_and_cropped_as_savefig_crops_them(tmp_path, monkeypatch):
    """``tight=True``: the drawn pixels cropped to the content plus savefig's margin, the
    picture that ``bbox_inches="tight"`` gives (which draws the figure three times)."""
    import io

    import matplotlib

    def loose() -> Figure:  # a figure with room around its one axes
        fig = Figure(figsize=(4, 3))
        ax = fig.add_axes((0.3, 0.3, 0.4, 0.4))
        ax.plot([0, 1], [0, 1])
        ax.set_xlabel("x (px)")
        return fig

    draws = []
    plain = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda fig, r: draws.append(1) or plain(fig, r))
    (path,) = save_figure(loose(), tmp_path / "t.png", dpi=100, tight=True)
    assert len(draws) == 1
    expected = io.BytesIO()
    loose().savefig(expected, format="png", dpi=100, bbox_inches="tight")
    expected.seek(0)
    mine, theirs = imread(path), imread(expected)
    # the same size to a pixel or two (savefig pads the text's box, not its ink) ...
    assert abs(mine.shape[0] - theirs.shape[0]) <= 3 and abs(mine.shape[1] - theirs.shape[1]) <= 3
    assert mine.shape[0] < 300 and mine.shape[1] < 400
    # ... with the margin on every side: a white border, then ink
    pad = round(matplotlib.rcParams["savefig.pad_inches"] * 100)
    ink = (mine[..., :3] < 0.9).any(axis=-1)
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    assert abs(rows[0] - pad) <= 1 and abs(mine.shape[0] - 1 - rows[-1] - pad) <= 1
    assert abs(cols[0] - pad) <= 1 and abs(mine.shape[1] - 1 - cols[-1] - pad) <= 1
    # content at the figure's edge: the margin is added in the figure's colour
    fig = Figure(figsize=(2, 1), facecolor="yellow")
    fig.add_axes((0, 0, 1, 1)).imshow(np.zeros((4, 8)), cmap="gray", aspect="auto")
    (edge,) = save_figure(fig, tmp_path / "edge.png", dpi=50, tight=True)
    full = imread(edge)
    assert full.shape[:2] == (50 + 2 * round(pad / 2), 100 + 2 * round(pad / 2))
    assert full[0, 0, :3].tolist() == [1, 1, 0] and full[25, 50, :3].tolist() == [0, 0, 0]
    # nothing drawn: the figure whole; a transparent figure: cropped to what is opaque
    (blank,) = save_figure(Figure(figsize=(2, 1)), tmp_path / "blank.png", dpi=50, tight=True)
    assert imread(blank).shape[:2] == (50, 100)
    clear = loose()
    clear.patch.set_alpha(0)
    (see,) = save_figure(clear, tmp_path / "clear.png", dpi=100, tight=True)
    assert imread(see).shape == mine.shape


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


# ------------------------------------------------------------------ principal crosses


def _arms(fig, gid):
    """The bars of one principal direction: (points, 2 ends, xy)."""
    (arms,) = [c for c in fig.axes[0].collections if c.get_gid() == gid]
    return np.array(arms.get_segments())


def test_principal_crosses_point_along_a_known_stretch(tmp_path):
    X = _grid(4)
    x = X * [1.2, 0.9]  # stretch along x, shortening along y: E1 = 0.22, E2 = -0.095
    field = compute_strain(X, np.stack([X, x]), grid_triangles(4, 4))
    image = _frames(1)[0]
    fig = plot_principal_crosses(image, field, 1, scale=100.0)
    arms = {c.get_gid(): c for c in fig.axes[0].collections if c.get_gid() in ("E1", "E2")}
    e1 = np.array(arms["E1"].get_segments())
    e2 = np.array(arms["E2"].get_segments())
    assert e1.shape == e2.shape == (16, 2, 2)
    d1, d2 = e1[:, 1] - e1[:, 0], e2[:, 1] - e2[:, 0]
    assert np.abs(d1[:, 1]).max() < 1e-9 and np.abs(d2[:, 0]).max() < 1e-9  # horizontal, vertical
    assert np.abs(d1[:, 0]) == pytest.approx(100 * 0.22)
    assert np.abs(d2[:, 1]) == pytest.approx(100 * 0.095)
    assert 0.5 * (e1[:, 0] + e1[:, 1]) == pytest.approx(x)  # centred on the current nodes
    assert to_rgba(arms["E1"].get_colors()[0]) == to_rgba("#b2182b")  # red: stretch
    assert to_rgba(arms["E2"].get_colors()[0]) == to_rgba("#2166ac")  # blue: shortening
    assert fig.axes[0].get_xlabel() == "x (px)"
    save_figure(fig, tmp_path / "crosses.png", dpi=80)
    _assert_image(tmp_path / "crosses.png")
    # default scale: the longest bar is 0.8 of the node spacing (in the current frame)
    fig = plot_principal_crosses(image, field, -1)
    e1 = _arms(fig, "E1")
    spacing = (X[4, 1] - X[0, 1]) * 0.9  # the shorter grid step (y) after deformation
    assert np.linalg.norm(e1[:, 1] - e1[:, 0], axis=1).max() == pytest.approx(0.8 * spacing)
    # triangles: one cross per triangle centroid
    fig = plot_principal_crosses(image, field, 1, at="triangles")
    assert len(_arms(fig, "E1")) == field.n_triangles
    with pytest.raises(ValueError, match="at must be"):
        plot_principal_crosses(image, field, 1, at="edges")


def test_principal_crosses_skip_nodes_without_values():
    n = 4
    X = _grid(n)
    x = np.stack([X, X * [1.1, 0.95]])
    x[1, 0] = np.nan  # a lost corner node: its only triangle is lost, it has no value
    field = compute_strain(X, x, grid_triangles(n, n))
    e1 = nodal_scalars(field)["E1"][1]
    assert np.isnan(e1[0]) and np.isfinite(e1[1:]).all()
    fig = plot_principal_crosses(_frames(1)[0], field, 1)
    seg = _arms(fig, "E1")
    assert len(seg) == n * n - 1
    assert np.isfinite(seg).all()


# ------------------------------------------------------------------ curves and violins


def test_mean_curves_and_their_figure(tmp_path):
    field = _field(T=6, noise=0.0)
    curves = mean_strain_curves(field, ("Exx", "Eyy"))
    s = np.linspace(0, 1, 6)
    assert curves["mean"]["Eyy"] == pytest.approx(0.5 * ((1 - 0.2 * s) ** 2 - 1))
    assert curves["sd"]["Exx"] == pytest.approx(np.zeros(6), abs=1e-12)
    assert list(curves["n"]["Exx"]) == [25] * 6
    noisy = _field(T=6)
    fig = plot_strain_curves(noisy, times=np.arange(6) / 5, time_unit="s", endpoint=4)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "Green-Lagrange strain (-)"
    assert any("endpoint" in t.get_text() and "0.8 s" in t.get_text() for t in ax.texts)
    save_figure(fig, tmp_path / "curves.png", dpi=60)
    _assert_image(tmp_path / "curves.png", shape=(int(4.2 * 60), int(7.0 * 60)))
    assert plot_strain_curves(noisy).axes[0].get_xlabel() == "frame"
    with pytest.raises(ValueError, match="one value per frame"):
        plot_strain_curves(noisy, times=[0, 1])
    # the curves, when at hand, are drawn as given (a streamed field is not read again)
    given = mean_strain_curves(noisy)
    drawn = plot_strain_curves(noisy, curves=given).axes[0].get_lines()[0].get_ydata()
    assert np.array_equal(drawn, given["mean"]["Exx"])
    assert np.array_equal(drawn, plot_strain_curves(noisy).axes[0].get_lines()[0].get_ydata())


def test_format_p():
    assert format_p(1e-9) == "p < 0.001"
    assert format_p(0.00999) == "p = 0.010"
    assert format_p(0.5) == "p = 0.50"
    assert format_p(float("nan")) == "p = n/a"


def test_violins_with_tests_and_degenerate_values(tmp_path):
    rng = np.random.default_rng(0)
    values = {"Exx": rng.normal(-0.1, 0.01, 49), "Eyy": rng.normal(-0.2, 0.02, 49)}
    values["Exx"][3] = np.nan
    tests = {"t_p": 2e-6, "wilcoxon_p": 0.0042, "n": 48, "label": "node-level paired t-test"}
    fig = plot_strain_violins(values, title="specimen 1", tests=tests)
    texts = " ".join(t.get_text() for t in fig.axes[0].texts)
    assert "node-level paired t-test: p < 0.001" in texts
    assert "Wilcoxon signed-rank: p = 0.004" in texts and "n = 48" in texts
    assert fig.axes[0].get_ylabel() == "Green-Lagrange strain (-)"
    save_figure(fig, tmp_path / "violins.png", dpi=60)
    _assert_image(tmp_path / "violins.png")
    # a uniform field (no spread), a single node, and no values at all still draw
    odd = {"Exx": np.full(10, -0.1), "Eyy": np.array([-0.2]), "Exy": np.array([np.nan])}
    save_figure(plot_strain_violins(odd, tests={"t_p": float("nan")}), tmp_path / "odd.png")
    _assert_image(tmp_path / "odd.png", min_colours=5)


def _boxes_apart(fig, a, b) -> bool:
    """Whether the drawn extents of artists ``a`` and ``b`` do not intersect."""
    fig.draw_without_rendering()
    return not a.get_window_extent().overlaps(b.get_window_extent())


def test_violin_legend_names_every_mark_and_covers_no_data():
    rng = np.random.default_rng(1)
    values = {"Exx": rng.normal(-0.1, 0.01, 49), "Eyy": rng.normal(-0.2, 0.02, 49)}
    fig = plot_strain_violins(values, tests={"t_p": 0.01, "n": 49})
    (legend,) = fig.legends
    names = [t.get_text() for t in legend.get_texts()]
    assert names == [
        "one node (jittered)", "median", "interquartile range",
        "violin: kernel density of the nodes",
    ]  # fmt: skip
    # the entries look like the marks: black median bar and IQR line, grey nodes
    node, median, iqr, _ = legend.legend_handles
    assert node.get_marker() == "o" and node.get_linestyle() == "None"
    assert to_rgba(median.get_color()) == to_rgba("k") and iqr.get_marker() == "|"
    ax = fig.axes[0]
    assert len(ax.collections) >= 2 + 2  # two violin bodies and two node scatters drawn
    assert _boxes_apart(fig, legend, ax)  # under the axes, over no node


def test_study_violins_lead_with_the_specimen_level_test():
    rng = np.random.default_rng(2)
    violins = [
        {
            "name": f"S{i}",
            "group": "g" if i < 2 else "h",
            "values": {"Exx": rng.normal(-0.1, 0.01, 25), "Eyy": rng.normal(-0.2, 0.01, 25)},
            "tests": {"t_p": 1e-6, "n": 25},
        }
        for i in range(4)
    ]
    levels = {"g": {"t_p": 0.0123, "wilcoxon_p": 0.5, "n": 2}, "h": {"t_p": 0.5, "n": 2}}
    fig = plot_study_violins(violins, tests=levels)
    head = fig.get_suptitle()
    assert head.startswith("specimen-level paired tests of")
    assert "g (n = 2 specimens): paired t-test p = 0.012, Wilcoxon p = 0.50" in head
    assert "h (n = 2 specimens): paired t-test p = 0.50" in head
    ax = fig.axes[0]
    assert "node-level, descriptive: nodes within a specimen are not independent" in (
        ax.get_title()
    )
    (legend,) = fig.legends
    names = [t.get_text() for t in legend.get_texts()]
    assert names[:2] == ["$E_{xx}$", "$E_{yy}$"]
    assert {"one node (jittered)", "median", "interquartile range"} <= set(names)
    assert _boxes_apart(fig, legend, ax)
    # without specimen-level results there is no headline to show
    assert plot_study_violins(violins).get_suptitle() == ""


# ------------------------------------------------------------------ animation


def test_mp4_animation_frames_size_and_content(tmp_path):
    import cv2

    field = _field(T=4)
    calls = []
    out = write_strain_animation(
        tmp_path / "strain.mp4",
        iter(_frames(4)),
        field,
        fps=5,
        progress=lambda done, total: calls.append((done, total)),
        max_width=400,
    )
    assert out == tmp_path / "strain.mp4"
    assert calls == [(1, 4), (2, 4), (3, 4), (4, 4)]
    cap = cv2.VideoCapture(str(out))
    try:
        assert cap.get(cv2.CAP_PROP_FRAME_COUNT) == 4
        # H.264, which web browsers play inside the HTML report (mp4v does not)
        fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode().lower()
        assert fourcc in ("h264", "avc1"), fourcc
        shown = []
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            shown.append(frame)
    finally:
        cap.release()
    assert len(shown) == 4
    h, w = shown[0].shape[:2]
    assert w == 400 and h % 2 == 0 and 100 < h < 400
    for frame in shown:
        assert frame.std() > 20 and len(np.unique(frame.reshape(-1, 3), axis=0)) > 50
    assert [p.name for p in tmp_path.iterdir()] == ["strain.mp4"]  # no temporary left


def test_gif_animation_and_mismatched_frame_counts(tmp_path):
    import imageio.v3 as iio

    field = _field(T=3)
    rng = np.random.default_rng(1)
    tall = [rng.uniform(0, 1, (400, W)) for _ in range(3)]  # float frames, taller than wide
    labels = [f"t = {k / 2:.1f} s" for k in range(3)]
    out = write_strain_animation(
        tmp_path / "strain.gif", tall, field, components=("E1",), time_labels=labels, max_width=400
    )
    gif = iio.imread(out, plugin="pillow", index=None)
    assert gif.shape[0] == 3
    assert gif.shape[1] <= 400 and gif.shape[1] % 2 == 0 and gif.shape[2] % 2 == 0
    assert gif[..., :3].std() > 20
    for name, frames in (("few", _frames(2)), ("many", _frames(4))):
        with pytest.raises(ValueError, match=r"field of 3 frames|field's 3 frames"):
            write_strain_animation(tmp_path / f"{name}.mp4", iter(frames), field)
        assert not (tmp_path / f"{name}.mp4").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["strain.gif"]
    with pytest.raises(ValueError, match=r"\.mp4 or \.gif"):
        write_strain_animation(tmp_path / "x.avi", _frames(3), field)
    with pytest.raises(ValueError, match="time_labels"):
        write_strain_animation(tmp_path / "x.gif", _frames(3), field, time_labels=["a"])


def _wavy_field(T=3, n=7):
    """A grid over a 120 x 160 frame in a sinusoidal field (every band used), a point lost."""
    x, y = np.meshgrid(np.linspace(20, 140, n), np.linspace(15, 105, n))
    X = np.column_stack([x.ravel(), y.ravel()])
    u = np.stack([4 * np.sin(X[:, 0] / 25) * np.cos(X[:, 1] / 30),
                  -3 * np.cos(X[:, 0] / 35) * np.sin(X[:, 1] / 20)], -1)  # fmt: skip
    pts = X + np.linspace(0, 1, T)[:, None, None] * u
    visible = np.ones((T, n * n), bool)
    visible[-1, n + 1] = False
    return compute_strain(X, pts, grid_triangles(n, n), visible=visible)


def _drawn_frame(image, field, k, label, components=("Exx", "Eyy")):
    """(the animation's frame k, the state it was drawn with)."""
    from strain2d.figures._animation import _animation_figure, _animation_frame
    from strain2d.figures._style import _colour_scale

    limits = strain_limits(field, components)
    scales = {c: _colour_scale(c, *limits[c]) for c in components}
    state = _animation_figure(image, field, components, scales, 0.6, 640, 100, None, label=label)
    rgb = _animation_frame(state, image, field, k, nodal_scalars(field), components, label)
    return rgb, state, scales


def test_animation_frame_looks_like_matplotlib_drawing_it():
    """The frame drawn without Matplotlib matches the figure Matplotlib draws with the same
    image, filled contours and mesh: placement, sampling, colours, bands and title."""
    from matplotlib.collections import LineCollection

    from strain2d.figures._maps import _draw_contours, _triangulation

    field = _wavy_field()
    k, label = 2, "frame 2 (t = 0.2 s)"
    image = np.random.default_rng(4).uniform(30, 220, (120, 160))  # speckle: shifts show
    rgb, state, scales = _drawn_frame(image, field, k, label)
    values = nodal_scalars(field)
    for ax, comp in zip(state["axes"], ("Exx", "Eyy"), strict=True):
        ax.images[0].set_data(image)
        tri = _triangulation(field, k, values[comp][k])
        _draw_contours(ax, tri, values[comp][k], scales[comp], 0.6)
        edges = np.stack([np.column_stack([tri.x[tri.edges[:, i]], tri.y[tri.edges[:, i]]])
                          for i in (0, 1)], axis=1)  # fmt: skip
        ax.add_collection(LineCollection(edges, colors="k", linewidths=0.3, alpha=0.45))
    state["label"].set_text(label)
    state["canvas"].draw()
    reference = np.asarray(state["canvas"].buffer_rgba())[: rgb.shape[0], : rgb.shape[1], :3]
    rows = state["title_rows"]
    assert rows > 5 and np.abs(rgb[:rows].astype(int) - reference[:rows]).max() <= 1
    assert rgb[:rows].min() < 100  # the title is there
    for panel in state["panels"]:
        ours = rgb[panel["window"]].astype(int)
        theirs = reference[panel["window"]].astype(int)
        diff = np.abs(ours - theirs).max(axis=-1)
        assert ours.shape[0] > 100 and ours.shape[1] > 150
        # one band off gives a mean of 10, a sampling half a pixel off 44
        assert diff.mean() < 7 and np.mean(diff > 40) < 0.06, (diff.mean(), np.mean(diff > 40))


def test_animation_frame_shows_each_value_in_its_band_colour_where_it_is():
    field = _wavy_field()
    k = 1
    image = np.full((120, 160), 128, np.uint8)
    rgb, state, scales = _drawn_frame(image, field, k, "frame 1")
    values = nodal_scalars(field)
    pos = field.points[k]
    for panel, comp in zip(state["panels"], ("Exx", "Eyy"), strict=True):
        sx, tx, sy, ty = panel["to_window"]
        scale = scales[comp]
        checked = 0
        for tri in field.triangles[field.element_valid[k]]:
            centre = pos[tri].mean(axis=0)  # the field is linear: its value is the mean
            corner = values[comp][k][tri]
            v = corner.mean()
            edges = np.array([pos[tri[1]] - pos[tri[0]], pos[tri[2]] - pos[tri[0]]])
            gradient = np.linalg.solve(edges, corner[1:] - corner[0])  # per image pixel
            if np.min(np.abs(scale.levels - v)) < 3 / sx * np.linalg.norm(gradient):
                continue  # a band's edge within 3 pixels of the output
            x = round(centre[0] * sx + tx) + panel["window"][1].start
            y = round(centre[1] * sy + ty) + panel["window"][0].start
            colour = np.array(scale.cmap(scale.norm(v))[:3]) * 255
            expected = 128 * 0.4 + colour * 0.6
            assert np.abs(rgb[y, x] - expected).max() <= 2, (comp, tri, rgb[y, x], expected)
            checked += 1
        assert checked > 20


def test_raster_triangles_lists_the_pixels_whose_centres_lie_inside():
    from strain2d.figures._animation import _raster_triangles

    rng = np.random.default_rng(7)
    corners = rng.uniform(-5, 45, (40, 3, 2))  # some reach outside the 30 x 40 raster
    corners[0] = [[3, 3], [3, 3], [9, 3]]  # no area
    corners[1] = [[10.0, 5.0], [20.0, 5.0], [15.0, 12.0]]  # a horizontal edge on a row
    rows, cols, tri = _raster_triangles(corners, (30, 40))
    assert rows.min() >= 0 and rows.max() < 30 and cols.min() >= 0 and cols.max() < 40
    yy, xx = np.mgrid[0:30, 0:40]
    for t, (a, b, c) in enumerate(corners):
        area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if area == 0:
            continue
        s = ((b[0] - xx) * (c[1] - yy) - (c[0] - xx) * (b[1] - yy)) / area
        q = ((c[0] - xx) * (a[1] - yy) - (a[0] - xx) * (c[1] - yy)) / area
        inside = (s >= -1e-9) & (q >= -1e-9) & (1 - s - q >= -1e-9)
        strictly = (s > 1e-9) & (q > 1e-9) & (1 - s - q > 1e-9)
        listed = np.zeros((30, 40), bool)
        listed[rows[tri == t], cols[tri == t]] = True
        assert not (listed & ~inside).any() and not (strictly & ~listed).any(), t
    assert {(r, c) for r, c in zip(rows[tri == 1], cols[tri == 1], strict=True)} >= {
        (5, c) for c in range(10, 21)
    }


def test_compiled_band_filling_gives_the_pixels_of_the_numpy_one():
    """The animation's compiled kernel against its NumPy path, bit for bit: meshes moved,
    scaled and reaching outside the raster, triangles without area or with a horizontal
    edge on a pixel row, every component's scale."""
    from strain2d.figures._animation import _bands, _fill_bands
    from strain2d.figures._style import _colour_scale

    rng = np.random.default_rng(11)
    field = _wavy_field()
    values = nodal_scalars(field)
    checked = 0
    for comp in ("Exx", "Eyy", "Exy"):
        finite = np.concatenate([v[np.isfinite(v)] for v in values[comp]])
        bands = _bands(_colour_scale(comp, float(finite.min()), float(finite.max())), 0.6)
        for k in range(field.n_frames):
            for scale, shift in ((1.0, 0.0), (2.7, -40.0), (0.4, 3.3), (3.1, 15.5)):
                xy = field.points[k] * scale + shift
                if checked % 3 == 0:
                    xy = xy.copy()
                    a, b, c = field.triangles[checked % len(field.triangles)]
                    xy[b] = xy[a]  # a triangle (or more) without area
                    xy[c, 1] = np.round(xy[a, 1])  # a horizontal edge on a row
                    xy[a, 1] = xy[c, 1]
                v = values[comp][k]
                good = field.element_valid[k] & np.all(np.isfinite(v[field.triangles]), axis=1)
                base = rng.uniform(0, 255, (130, 170, 3)).astype(np.float32)
                plain, compiled = base.copy(), base.copy()
                _fill_bands(plain, xy, v, field.triangles, good, bands)
                _fill_bands(compiled, xy, v, field.triangles, good, bands, compiled=True)
                assert np.array_equal(plain, compiled), (comp, k, scale)
                checked += (plain != base).any()
    assert checked > 30


def test_compiled_animation_frames_are_the_numpy_ones():
    """Whole frames drawn through the compiled kernels (the gray frame sampled, the bands,
    the panel put in place) against the NumPy path, bit for bit: an 8-bit frame, a float
    frame (its gray through NumPy either way), a frame of another size."""
    from strain2d.figures._animation import _animation_frame

    field = _wavy_field()
    values = nodal_scalars(field)
    rng = np.random.default_rng(5)
    for image in (
        rng.uniform(0, 255, (120, 160)).astype(np.uint8),
        rng.uniform(30, 220, (120, 160)),
    ):
        _, state, _ = _drawn_frame(image, field, 0, "frame 0")
        for k, shown in ((1, image), (2, image[::2, ::2].copy())):
            frames = []
            for compiled in (False, True):
                state["compiled"] = compiled
                frames.append(_animation_frame(state, shown, field, k, values, ("Exx", "Eyy"), "f"))
            assert np.array_equal(*frames), (image.dtype, k)


def test_animation_title_is_each_frames_label_over_the_same_figure():
    field = _wavy_field()
    image = np.random.default_rng(2).uniform(0, 255, (120, 160)).astype(np.uint8)
    from strain2d.figures._animation import _animation_frame

    first, state, _ = _drawn_frame(image, field, 0, "frame 0 / 2")
    values = nodal_scalars(field)
    second = _animation_frame(state, image, field, 0, values, ("Exx", "Eyy"), "frame 1 / 2")
    rows = state["title_rows"]
    assert (first[:rows] != second[:rows]).any()  # another label
    assert (first[rows:] == second[rows:]).all()  # the same frame and figure below it


# ------------------------------------------------------------------ figures drawn by workers


def _font_size():
    import warnings

    import matplotlib

    warnings.warn("drawn elsewhere", UserWarning, stacklevel=1)
    return matplotlib.rcParams["font.size"], os.getpid()


def _refuse():
    raise InputError("frame 3: no strain")


def _wait_for(path):
    while not os.path.exists(path):
        time.sleep(0.01)


@pytest.mark.parametrize("threads", [1, 2], ids=["forked", "from-a-server"])
def test_figure_pool_runs_tasks_elsewhere_as_they_would_run_here(tmp_path, threads):
    """Workers forked from this process, or (another thread running here, when forking is
    unsafe) from a fresh server: the caller's style, its warnings and errors either way."""
    import threading

    import matplotlib

    from strain2d.figures._pool import FigurePool, _context

    done = threading.Event()
    others = [threading.Thread(target=done.wait) for _ in range(threads - 1)]
    for thread in others:
        thread.start()
    try:
        method, alive = _context().get_start_method(), threading.active_count()
        with matplotlib.rc_context({"font.size": 7.5}), FigurePool(1) as pool:
            pending = pool.submit(_font_size)
            with pytest.warns(UserWarning, match="drawn elsewhere"):
                size, pid = pending.result()  # the caller's style; its warning raised here
            assert size == 7.5 and pid != os.getpid()
            with pytest.raises(InputError, match="frame 3: no strain"):
                pool.submit(_refuse).result()
    finally:
        done.set()
    if sys.platform.startswith("linux"):
        assert method == ("fork" if alive == 1 else "forkserver")
    with FigurePool(0) as pool:  # here, at once
        with pytest.warns(UserWarning, match="drawn elsewhere"):
            assert pool.submit(_font_size).result()[1] == os.getpid()


def test_a_warm_pool_loads_matplotlib_in_its_workers_not_here():
    """``warm=True`` (a pool started before the tracking): the workers load Matplotlib's
    drawing themselves, ready for the figures, and this process does not."""
    import subprocess

    code = (
        "import os, sys\n"
        "from strain2d.figures._pool import FigurePool\n"
        "def loaded():\n"
        "    from matplotlib.mathtext import MathTextParser\n"
        "    agg = 'matplotlib.backends.backend_agg' in sys.modules\n"
        "    return [agg, MathTextParser._parser is not None], os.getpid()\n"
        "if __name__ == '__main__':\n"
        "    with FigurePool(2, warm=True) as pool:\n"
        "        there, pid = pool.submit(loaded).result()\n"
        "    print(there, pid != os.getpid(), loaded()[0])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[True, True] True [False, False]"


def _touch(path):
    open(path, "w").close()


def test_figure_pool_hands_a_task_to_a_worker_as_it_becomes_idle(tmp_path):
    """A task queued behind another starts once the worker is free, while the caller works
    on without calling the pool (as it does while it writes the animation)."""
    from strain2d.figures._pool import FigurePool

    go, second = tmp_path / "go", tmp_path / "second"
    with FigurePool(1) as pool:
        first = pool.submit(_wait_for, go)  # keeps the only worker busy until "go"
        queued = pool.submit(_touch, second)
        go.touch()
        waited = 0.0
        while not second.exists() and waited < 60:  # no call to the pool meanwhile
            time.sleep(0.01)
            waited += 0.01
        assert second.exists()
        first.result(), queued.result()


def test_figure_pool_fails_a_task_whose_call_or_reply_cannot_travel_and_goes_on():
    """A task whose arguments raise as they are pickled (here an OSError, as a file-backed
    object may), or whose error cannot be rebuilt here: that task's error, raised here,
    and the workers go on with the next tasks (run in a subprocess: a pool that waited
    forever would fail it, not hang the tests)."""
    code = (
        "import os\n"
        "from strain2d.figures._pool import FigurePool\n"
        "class Unreadable:\n"
        "    def __reduce__(self):\n"
        "        raise FileNotFoundError('the file behind it is gone')\n"
        "class TwoArgError(Exception):\n"
        "    def __init__(self, what, why):\n"
        "        super().__init__(f'{what}: {why}')\n"
        "def fail():\n"
        "    raise TwoArgError('frame 3', 'no strain')\n"
        "def ident(x):\n"
        "    return x, os.getpid()\n"
        "if __name__ == '__main__':\n"
        "    with FigurePool(2) as pool:\n"
        "        for task in (pool.submit(ident, Unreadable()), pool.submit(fail)):\n"
        "            try:\n"
        "                task.result()\n"
        "            except Exception as exc:\n"
        "                print(type(exc).__name__)\n"
        "        value, pid = pool.submit(ident, 7).result()\n"
        "        print(value, pid != os.getpid(), all(p.is_alive() for p in pool._processes))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.split() == ["FileNotFoundError", "TypeError", "7", "True", "True"]


def test_figure_pool_ends_its_workers_when_left_by_an_error(tmp_path):
    from strain2d.figures._pool import FigurePool

    with pytest.raises(KeyboardInterrupt), FigurePool(2) as pool:
        pids = [process.pid for process in pool._processes]
        for _ in range(3):
            pool.submit(_wait_for, tmp_path / "never")  # busy until ended, and one waiting
        raise KeyboardInterrupt
    assert len(pids) == 2
    for pid in pids:  # ended and reaped before the caller goes on to remove their folder
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


# ------------------------------------------------------------------ study figures


def _study():
    specs = [("S1", "aniso", 0.1, 0.2), ("S2", "iso", 0.15, 0.15), ("S3", "aniso", 0.1, 0.25)]
    curves, violins, table = [], [], []
    for i, (name, group, ax, ay) in enumerate(specs):
        field = _field(T=4, ax=ax, ay=ay, seed=i)
        stats = mean_strain_curves(field, ("Exx", "Eyy"))
        curves.append(
            {"name": name, "group": group, "times": np.arange(4) * 0.5, **stats, "endpoint": 2}
        )
        node = nodal_scalars(field)
        values = {"Exx": node["Exx"][-1], "Eyy": node["Eyy"][-1]}
        tests = {"t_p": 1e-4 if ax != ay else 0.4, "n": 25, "label": "node-level paired t-test"}
        violins.append({"name": name, "group": group, "values": values, "tests": tests})
        means = {k: float(v.mean()) for k, v in values.items()}
        table.append({"name": name, "group": group, **means})
    return curves, violins, table


def test_study_figures(tmp_path):
    curves, violins, table = _study()
    fig = plot_study_curves(curves, time_unit="s")
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in panels] == ["S1 (aniso)", "S3 (aniso)", "S2 (iso)"]
    assert all(ax.get_xlabel() == "time (s)" for ax in panels)
    assert panels[0].get_ylim() == panels[2].get_ylim()  # one strain axis
    assert any("endpoint (1 s)" in t.get_text() for t in panels[0].texts)
    curves[1]["endpoint"] = 0.75  # a time, not an index
    save_figure(plot_study_curves(curves), tmp_path / "curves.png", dpi=50)
    _assert_image(tmp_path / "curves.png")

    fig = plot_study_violins(violins)
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["S1", "S3", "S2"]
    ptexts = sorted(t.get_text() for t in ax.texts if t.get_text().startswith("p "))
    assert ptexts == ["p < 0.001", "p < 0.001", "p = 0.40"]
    assert ax.get_ylabel() == "Green-Lagrange strain (-)"
    save_figure(fig, tmp_path / "violins.png", dpi=50)
    _assert_image(tmp_path / "violins.png")
    with pytest.raises(ValueError, match="no values for"):
        plot_study_violins(violins, components=("Exx", "Exy"))

    fig = plot_specimen_means(table, tests={"aniso": {"t_p": 0.03}, "iso": {"t_p": 0.9}})
    ax = fig.axes[0]
    assert len(ax.get_lines()) == len(table) + 2 + 1  # specimens, group means, zero
    assert "aniso: paired t-test p = 0.030" in ax.get_title()
    assert "specimen mean" in ax.get_ylabel() and "(-)" in ax.get_ylabel()
    assert f"(n = {len(table)} specimens)" in ax.get_title()
    lost = [*table[:2], {**table[2], "Exx": float("nan")}]  # a specimen without a mean
    title = plot_specimen_means(lost).axes[0].get_title()
    assert "(n = 2 specimens; 1 without a mean left out)" in title.replace("\n", " ")
    nested = [{"name": r["name"], "mean": {"Exx": r["Exx"], "Eyy": r["Eyy"]}} for r in table]
    save_figure(plot_specimen_means(nested), tmp_path / "means.png", dpi=50)
    _assert_image(tmp_path / "means.png")


def test_figures_never_touch_pyplot(tmp_path):
    code = (
        "import sys, numpy as np\n"
        "from strain2d import figures as f\n"
        "from surface_strain import compute_strain, grid_triangles\n"
        "X = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2) * 10\n"
        "field = compute_strain(X, np.stack([X, X * 1.1]), grid_triangles(3, 3))\n"
        "img = np.zeros((30, 30))\n"
        f"f.save_figure(f.plot_principal_crosses(img, field, 1), {str(tmp_path / 'c')!r})\n"
        f"f.write_strain_animation({str(tmp_path / 'a.mp4')!r}, [img, img], field)\n"
        "assert 'matplotlib.pyplot' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_limits_cover_the_frames_drawn_as_maps():
    """A stretch that ends at its peak: no node of the last frame in the end colours."""
    from strain2d.figures import strain_limits
    from surface_strain import compute_strain, grid_triangles, nodal_scalars

    rng = np.random.default_rng(0)
    X = np.stack(np.meshgrid(np.arange(7.0), np.arange(7.0)), -1).reshape(-1, 2)
    frames = [X * (1 + 0.025 * k) + (rng.normal(0, 1e-3, X.shape) if k else 0) for k in range(31)]
    field = compute_strain(X, np.stack(frames), grid_triangles(7, 7))
    last = nodal_scalars(field)["Exx"][-1]
    lo, hi = strain_limits(field, ["Exx"])["Exx"]
    assert (last > hi).mean() > 0.05  # the 0.5 % percentile alone saturates the peak frame
    lo, hi = strain_limits(field, ["Exx"], cover=[30])["Exx"]
    assert lo <= last.min() and last.max() <= hi


@pytest.mark.parametrize("shape", [(1080, 1920), (300, 200), (97, 131)])
def test_frames_are_shown_with_the_pixels_colouring_them_first_would_give(shape):
    """A frame under a figure is sampled to the panel and coloured then, not coloured whole
    first: the same pixels, down-sampled (a large frame), up-sampled or near 1:1."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from strain2d.figures._maps import _show_image

    image = np.random.default_rng(0).uniform(0, 255, shape).astype(np.float32)
    drawn = []
    for stage in ("data", "rgba"):
        fig = Figure(figsize=(5, 3.5), dpi=150)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.1, 0.1, 0.8, 0.8))
        ax.imshow(image, cmap="gray", interpolation="nearest", interpolation_stage=stage)
        ax.set_xlim(-0.5, shape[1] - 0.5)
        ax.set_ylim(shape[0] - 0.5, -0.5)
        canvas.draw()
        drawn.append(np.asarray(canvas.buffer_rgba()).copy())
    np.testing.assert_array_equal(drawn[0], drawn[1])
    artist = _show_image(Figure().add_subplot(), image)
    assert (artist.get_interpolation(), artist.get_interpolation_stage()) == ("nearest", "data")

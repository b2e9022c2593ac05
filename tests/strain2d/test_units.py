"""Physical units: ``--scale`` and ``--scale-ruler`` reach every table, figure, report and .vtp."""

import json
import re

import matplotlib
import numpy as np
import pytest

from strain2d.cli import main
from strain2d.scale import PixelScale, parse_scale, scale_from_ruler
from tissue_core.errors import InputError
from tissue_core.tables import read_long_table


@pytest.mark.parametrize(
    ("text", "per_px", "unit"),
    [
        ("0.012mm/px", 0.012, "mm"),
        ("12 um/px", 12.0, "um"),
        ("12µm/px", 12.0, "um"),
        ("83.3px/mm", 1 / 83.3, "mm"),
        ("2.5e-3 cm / px", 2.5e-3, "cm"),
    ],
)
def test_scale_parses_both_ways(text, per_px, unit):
    scale = parse_scale(text)
    assert scale.unit == unit and scale.per_px == pytest.approx(per_px, rel=1e-12)
    assert PixelScale.from_json(scale.to_json()) == scale


@pytest.mark.parametrize(
    "text", ["0.012", "mm/px", "0.012 inch/px", "-1mm/px", "0mm/px", "x", "", "1e-320mm/px"]
)
def test_a_bad_scale_is_one_clear_error(text):
    with pytest.raises(InputError, match=r"--scale|positive"):
        parse_scale(text)


def test_a_ruler_measures_the_pixel_size():
    # 3-4-5: the points are 500 px apart
    scale = scale_from_ruler("100,100,400,500:6mm", (600, 600))
    assert scale.unit == "mm" and scale.per_px == pytest.approx(6 / 500, rel=1e-12)
    with pytest.raises(InputError, match="outside the 600x600 px frame"):
        scale_from_ruler("100,100,700,500:6mm", (600, 600))
    with pytest.raises(InputError, match="at least 10 px apart"):
        scale_from_ruler("100,100,103,100:6mm")
    with pytest.raises(InputError, match="X0,Y0,X1,Y1:LENGTH"):
        scale_from_ruler("100,100,400:6mm")


def _svg_text(path):
    return " ".join(re.findall(r">([^<>]+)</text>", path.read_text()))


def test_a_scaled_run_writes_mm_in_every_table_figure_report_and_vtp(small_case, tmp_path):
    import pyvista as pv

    folder, _ = small_case
    out = tmp_path / "run"
    args = ["-q", "analyze", str(folder / "eq.tif"), "--grid", "4x4", "--tracker", "gdic"]
    args += ["--fps", "5", "--animation", "none", "--figure-format", "svg"]
    # SVG text kept as text, so that the axis labels can be read back
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        assert main([*args, "--scale", "0.02mm/px", "--out", str(out)]) == 0

    tracks = read_long_table(out / "tracks.csv", required=("x", "y", "x_mm", "y_mm"))
    assert np.allclose(tracks["x_mm"], 0.02 * tracks["x"], atol=1e-7)
    assert np.allclose(tracks["y_mm"], 0.02 * tracks["y"], atol=1e-7)
    nodes = read_long_table(
        out / "strain_nodes.csv", required=("x", "u", "v", "x_mm", "y_mm", "u_mm", "v_mm")
    )
    assert np.allclose(nodes["u_mm"], 0.02 * nodes["u"], atol=1e-7)
    assert np.allclose(nodes["v_mm"], 0.02 * nodes["v"], atol=1e-7)
    assert np.abs(nodes["u"][-1]).max() > 1  # the video deforms: the check is not of zeros
    header = (out / "strain_nodes.csv").read_text().splitlines()[0].split(",")
    assert "uncertainty_px" in header and "uncertainty_mm" in header  # gdic measures it

    summary = json.loads((out / "summary.json").read_text())
    units = summary["units"]
    assert units["length"] == "mm" and units["scale"]["length_per_px"] == 0.02
    assert units["time"] == "s"
    assert units["columns"]["strain_nodes.csv"]["u_mm"] == "mm"
    assert set(header) <= set(units["columns"]["strain_nodes.csv"]) | {"frame", "point"}

    # ParaView: points and displacement in mm, units named in the field data
    last = sorted((out / "strain").glob("*.vtp"))[-1]
    mesh = pv.read(last)
    T = int(nodes["x"].shape[0])
    assert np.allclose(mesh.points[:, 0], 0.02 * nodes["x"][T - 1], atol=1e-5)
    assert np.allclose(mesh.point_data["displacement"][:, 1], 0.02 * nodes["v"][T - 1], atol=1e-5)
    assert list(mesh.field_data["length_unit"]) == ["mm"]
    assert list(mesh.field_data["time_unit"]) == ["s"]
    named = dict(u.split(": ", 1) for u in mesh.field_data["array_units"])
    assert named["point displacement"] == "mm" and named["point Exx"].startswith("1")
    assert set(named) >= {f"point {k}" for k in mesh.point_data.keys()}

    # every figure with image axes says mm, none says px
    svgs = sorted((out / "figures").glob("*.svg"))
    assert len(svgs) >= 5
    plots = ("strain_curves", "violins", "tracking_quality")  # time axes, no image
    image_figures = [p for p in svgs if not p.name.startswith(plots)]
    assert len(image_figures) >= 3
    for svg in image_figures:
        text = _svg_text(svg)
        assert "x (mm)" in text and "y (mm)" in text, svg.name
    for svg in svgs:
        assert "(px)" not in _svg_text(svg), svg.name
    assert "time (s)" in _svg_text(out / "figures" / "strain_curves.svg")
    assert "uncertainty (mm, 1 sigma)" in _svg_text(out / "figures" / "tracking_quality.svg")

    report = (out / "report.html").read_text()
    assert "0.02 mm/px" in report
    assert summary["input_files"][0]["sha256"] and summary["input_files"][0]["sha256"] in report
    assert "Quality of the measurement" in report and "What was flagged" in report
    from tests.report_browser import problems

    assert problems(out / "report.html") == []


def test_without_a_scale_positions_stay_in_pixels(small_case, tmp_path):
    import pyvista as pv

    folder, _ = small_case
    out = tmp_path / "run"
    args = ["-q", "analyze", str(folder / "eq.tif"), "--grid", "3x3", "--tracker", "klt"]
    assert main([*args, "--animation", "none", "--out", str(out)]) == 0
    header = (out / "strain_nodes.csv").read_text().splitlines()[0]
    assert "_mm" not in header and header.startswith("frame,point,x,y,u,v,visible,Exx")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["units"]["length"] == "px" and summary["units"]["scale"] is None
    mesh = pv.read(sorted((out / "strain").glob("*.vtp"))[-1])
    assert list(mesh.field_data["length_unit"]) == ["px"]
    assert list(mesh.field_data["time_unit"]) == ["frame"]


def test_the_ruler_is_checked_against_the_frame_before_tracking(small_case, tmp_path, capsys):
    folder, _ = small_case
    args = ["-q", "analyze", str(folder / "eq.tif"), "--grid", "3x3", "--out", str(tmp_path / "r")]
    assert main([*args, "--scale-ruler", "10,10,900,10:5mm"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "outside the 200x200 px frame" in err[0]
    assert not (tmp_path / "r").exists()
    with pytest.raises(SystemExit) as exit_:
        main([*args, "--scale", "0.01mm/px", "--scale-ruler", "10,10,90,10:5mm"])
    assert exit_.value.code == 2 and "not allowed with" in capsys.readouterr().err


def test_the_animation_axes_are_in_the_scale_unit(small_case):
    from strain2d.figures._animation import _animation_figure
    from strain2d.figures._style import _colour_scale
    from strain2d.pipeline import strain_from_tracks
    from strain2d.tracks import Tracks

    _, video = small_case
    g = np.array([[50.0, 50], [150, 50], [50, 150], [150, 150]])
    tracks = Tracks(np.stack([g, g * 1.01]), np.ones((2, 4), bool), np.ones((2, 4)))
    field = strain_from_tracks(tracks, grid_shape=(2, 2))
    scales = {"Exx": _colour_scale("Exx", 0.0, 0.1)}
    state = _animation_figure(
        video.frames[0], field, ["Exx"], scales, 0.6, 480, 100, parse_scale("0.5um/px")
    )
    ax = state["axes"][0]
    assert ax.get_xlabel() == "x (um)" and ax.get_ylabel() == "y (um)"
    ticks = [float(t.get_text()) for t in ax.get_xticklabels() if t.get_text()]
    assert ticks and max(ticks) <= 100 and all(t == round(t) for t in ticks)


def test_scale_auto_reads_the_pixel_size_a_tiff_records(tmp_path, small_case):
    """ImageJ/Fiji's calibration, OME's PhysicalSizeX and a resolution in cm; inches refused."""
    import tifffile

    from strain2d.scale import scale_from_file

    _, video = small_case
    frames = video.frames
    ij = tmp_path / "ij.tif"
    tifffile.imwrite(
        ij, frames, imagej=True, resolution=(2.0, 2.0), metadata={"unit": "micron", "axes": "TYX"}
    )
    scale = scale_from_file(ij)
    assert (scale.per_px, scale.unit) == (0.5, "um")
    ome = tmp_path / "ome.ome.tif"
    tifffile.imwrite(ome, frames, metadata={"axes": "TYX", "PhysicalSizeX": 0.25,
                                            "PhysicalSizeXUnit": "mm"})  # fmt: skip
    scale = scale_from_file(ome)
    assert (scale.per_px, scale.unit) == (0.25, "mm")
    cm = tmp_path / "cm.tif"
    tifffile.imwrite(cm, frames, resolution=(400.0, 400.0), resolutionunit="CENTIMETER")
    scale = scale_from_file(cm)
    assert scale.unit == "mm" and scale.per_px == pytest.approx(0.025)
    inch = tmp_path / "inch.tif"
    tifffile.imwrite(inch, frames, resolution=(72.0, 72.0), resolutionunit="INCH")
    with pytest.raises(InputError, match="print setting"):
        scale_from_file(inch)
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, frames)
    with pytest.raises(InputError, match="records no pixel size"):
        scale_from_file(plain)

    out = tmp_path / "run"
    args = ["-q", "analyze", str(ij), "--grid", "3x3", "--tracker", "klt", "--animation", "none"]
    assert main([*args, "--scale", "auto", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["units"]["scale"]["length_per_px"] == 0.5
    assert "ImageJ calibration" in summary["units"]["scale"]["source"]
    assert "x_um" in (out / "tracks.csv").read_text().splitlines()[0]

"""Repeated contractions in 3D runs: a curved sheet that twitches three times."""

import csv
import json

import numpy as np

from sample_data_synth.twitches import make_repeated_twitches
from surface_strain import choose_mesh, write_run


def test_a_3d_run_finds_the_cycles_of_a_curved_sheet(tmp_path):
    """The rendered twitches' exact motion, on a cylinder-shaped sheet in mm: every onset and
    peak to the frame, cycles.csv and the report's table; one twitch alone gives none."""
    truth = make_repeated_twitches(shape=(60, 80), n_frames=46).video.truth
    grid = truth.grid((9, 7))
    xy = truth.positions(grid)  # (T, N, 2) px
    z = 0.002 * (xy[..., 0] - 40) ** 2  # a gentle curve across the fibres
    points = np.concatenate([xy * 0.05, z[..., None]], axis=-1)  # mm
    visible = np.ones(points.shape[:2], bool)
    mesh = choose_mesh(points[0], grid=(9, 7))
    (tmp_path / "run").mkdir()
    write_run(tmp_path / "run", points, visible, mesh, fps=10)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    # the peak of the largest cycle beside the last frame: its statistics and maps
    peak = summary["peak_statistics"]
    assert peak["frame"] == 8 and peak["cycle"] == 1
    assert peak["Exx"]["mean"] < 0.9 * summary["last_frame_statistics"]["Exx"]["mean"] - 0.01
    assert (tmp_path / "run" / "figures" / "E1_frame0008.png").exists()
    assert "Strain at the peak of cycle 1" in (tmp_path / "run" / "report.html").read_text()
    found = summary["cycles"]["cycles"]
    true = truth.time_profile.cycles
    assert [(c["onset"], c["peak"]) for c in found] == [(t["onset"], t["peak"]) for t in true]
    with open(tmp_path / "run" / "cycles.csv", newline="") as f:
        assert [int(r["peak"]) for r in csv.DictReader(f)] == [t["peak"] for t in true]
    assert "Repeated contractions" in (tmp_path / "run" / "report.html").read_text()
    # one twitch: one cycle, not repeated
    (tmp_path / "one").mkdir()
    write_run(tmp_path / "one", points[:16], visible[:16], mesh, fps=10, figures=False)
    one = json.loads((tmp_path / "one" / "summary.json").read_text())["cycles"]
    assert [(c["onset"], c["peak"]) for c in one["cycles"]] == [(3, 8)] and not one["repeated"]

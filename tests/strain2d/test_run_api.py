"""A run folder from the Python API equals the command line's (strain2d.write_run)."""

import json
from pathlib import Path

import numpy as np

from strain2d import analyze, load_run, make_grid, open_frames, write_run
from strain2d.cli import main
from tissue_core.outputs import MARKER

# what may differ between two runs of the same analysis: when and how it was asked for
VOLATILE = ("created", "command", "runtime_s")


def _summary(folder):
    summary = json.loads((folder / "summary.json").read_text())
    return {k: v for k, v in summary.items() if k not in VOLATILE}


def test_write_run_makes_the_folder_analyze_makes(small_case, tmp_path):
    folder, _ = small_case
    video = folder / "eq.tif"
    options = ["--grid", "4x4", "--tracker", "klt", "--animation", "gif", "--fps", "5"]
    assert main(["-q", "analyze", str(video), *options, "--out", str(tmp_path / "cli")]) == 0

    frames = open_frames(video)
    grid = make_grid(frames.shape, shape=(4, 4))
    result = analyze(frames, grid, tracker="klt", grid_shape=(4, 4))
    summary = write_run(tmp_path / "api", result, frames, fps=5, animation="gif")

    cli, api = tmp_path / "cli", tmp_path / "api"
    files = sorted(p.relative_to(cli) for p in cli.rglob("*") if p.is_file())
    # the command's own log is the one file more: the API has no command to log
    assert "tracking 16 points (klt)" in (cli / "run.log").read_text()
    files.remove(Path("run.log"))
    assert files == sorted(p.relative_to(api) for p in api.rglob("*") if p.is_file())
    assert len(files) > 10
    differ = [
        str(f)
        for f in files
        if f.name not in ("summary.json", "report.html", MARKER)
        and (cli / f).read_bytes() != (api / f).read_bytes()
    ]
    assert differ == []
    from_cli = _summary(cli)
    from_cli["outputs"].remove("run.log")
    assert _summary(api) == from_cli
    assert summary["schema"] == 1 and summary["inputs"] == [str(video)]
    assert json.loads((cli / "summary.json").read_text())["command"][:2] == ["strain2d", "-q"]

    run = load_run(api)
    assert run.time_unit == "s" and np.allclose(run.times, np.arange(run.n_frames) / 5)
    assert np.array_equal(run.positions, load_run(cli).positions, equal_nan=True)


def test_write_run_takes_an_analysis_built_by_hand_and_refuses_a_generator(tmp_path):
    """Analysis(tracks, field): the tracker is the tracks'; frames are read twice."""
    import pytest

    from sample_data_synth import make_case
    from strain2d import InputError, track
    from strain2d.pipeline import Analysis, strain_from_tracks

    video = make_case("equibiaxial", size=160, n_frames=4)
    grid = make_grid((160, 160), shape=(3, 3), roi=video.truth.roi)
    tracks = track(video.frames, grid, tracker="klt")
    analysis = Analysis(tracks, strain_from_tracks(tracks))
    with pytest.raises(InputError, match="not generator"):
        write_run(tmp_path / "g", analysis, (f for f in video.frames), animation="none")
    assert not (tmp_path / "g").exists()
    summary = write_run(tmp_path / "a", analysis, lambda: iter(video.frames), animation="none")
    assert summary["tracker"]["name"] == "klt"
    assert summary["mesh"]["method"] == "given" and summary["source"]["kind"] == "array"
    assert load_run(tmp_path / "a").n_points == 9


def test_figures_drawn_by_worker_processes_are_those_drawn_here(small_case, tmp_path):
    """write_run's workers (the default where there are cores) write the same files, in the
    caller's Matplotlib style, as drawing every figure in this process."""
    import matplotlib

    from tissue_core.batch import differences

    folder, _ = small_case
    frames = open_frames(folder / "eq.tif")
    result = analyze(frames, make_grid(frames.shape, shape=(4, 4)), tracker="klt")
    options = {"animation": "mp4", "maps_at": [1], "figure_format": "png,svg"}
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        here = write_run(tmp_path / "here", result, frames, workers=0, **options)
        there = write_run(tmp_path / "there", result, frames, workers=2, **options)
    assert differences(tmp_path / "here", tmp_path / "there") == []
    assert here["figures"] == there["figures"] and len(here["figures"]) == 8
    svg = (tmp_path / "there" / "figures" / "strain_frame0001.svg").read_text()
    assert "</text>" in svg  # drawn with the caller's svg.fonttype
    assert set(there["runtime_s"]) >= {"tables", "animation", "figures", "report", "outputs"}

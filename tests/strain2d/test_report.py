"""Run and study outputs through the command line: figures, statistics, endpoint, report.html."""

from __future__ import annotations

import json
from html.parser import HTMLParser

import numpy as np
import pytest

from strain2d.cli import main
from strain2d.errors import InputError
from strain2d.report import endpoint_of, parse_formats
from surface_strain import compute_strain, grid_triangles
from tests.tolerances import STUDY_TRACKED_MEAN_STRAIN


class _Links(HTMLParser):
    """Every src/href of a document, the <img>/<video> count and the visible text."""

    def __init__(self):
        super().__init__()
        self.links, self.media, self.text = [], 0, []

    def handle_starttag(self, tag, attrs):
        self.media += tag in ("img", "video", "svg")
        self.links += [v for k, v in attrs if k in ("src", "href") and v is not None]

    def handle_data(self, data):
        self.text.append(data)


def _parse(path):
    p = _Links()
    p.feed(path.read_text(encoding="utf-8"))
    return p


def _analyze(small_case, out, *extra):
    folder, video = small_case
    x0, y0, x1, y1 = video.truth.roi
    argv = [
        "-q", "analyze", str(folder / "eq.avi"), "--grid", "4x4",
        "--roi", f"{x0},{y0},{x1},{y1}", "--tracker", "klt", "--window", "21",
        "--out", str(out), *extra,
    ]  # fmt: skip
    assert main(argv) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def run_dir(small_case, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "run"
    summary = _analyze(small_case, out, "--figure-format", "png,svg,pdf", "--maps-at", "2")
    return out, summary


@pytest.mark.xdist_group("strain2d_report_run")  # run_dir made once, on one worker
def test_run_folder_has_every_figure_and_the_statistics(run_dir):
    out, summary = run_dir
    ep = summary["contraction_endpoint"]
    # the equibiaxial video stretches until its last frame: no hold, endpoint = last frame
    assert ep["frame"] == 5 and ep["source"] == "not reached: still deforming at the last frame"
    figs = out / "figures"
    for stem in ("strain_frame0002", "strain_frame0005", "principal_directions_frame0005",
                 "strain_curves", "violins_frame0005", "tracked_grid"):  # fmt: skip
        for fmt in ("png", "svg", "pdf"):
            assert (figs / f"{stem}.{fmt}").is_file(), f"{stem}.{fmt}"
    assert (figs / "strain_animation.mp4").stat().st_size > 1000
    stats = json.loads((out / "statistics.json").read_text())
    assert stats["frame"] == 5
    assert stats["nodal_strain"]["Exx"]["n"] == 16
    assert abs(stats["nodal_strain"]["Exx"]["mean"] - 0.625) < 0.02
    paired = stats["paired"]
    assert paired["components"] == ["Exx", "Eyy"] and paired["n"] == 16
    assert "node-level" in paired["note"]
    assert summary["statistics"] == stats
    listed = {f for item in summary["figures"] for f in item["files"]}
    assert "figures/strain_animation.mp4" in listed and "figures/tracked_grid.svg" in listed
    assert all((out / f).is_file() for f in listed)
    assert {"report.html", "statistics.json"} <= set(summary["outputs"])


@pytest.mark.xdist_group("strain2d_report_run")  # run_dir made once, on one worker
def test_run_report_is_self_contained(run_dir):
    out, summary = run_dir
    page = _parse(out / "report.html")
    assert page.links, "figures must be embedded"
    assert all(link.startswith("data:") for link in page.links), [
        link[:40] for link in page.links if not link.startswith("data:")
    ]
    # tracked grid, 2 maps, crosses, curves, violins (PNG) and the animation (MP4)
    assert page.media >= 7
    text = " ".join(page.text)
    assert summary["software"]["version"] in text
    # the endpoint's heading names the deformation (this video stretches)
    label = summary["contraction_endpoint"]["label"]
    assert "stretch" in label and "eq.avi" in text and label.capitalize() in text
    assert "node-level paired tests" in text


def test_endpoint_can_be_given_and_animation_as_gif(small_case, tmp_path):
    summary = _analyze(small_case, tmp_path / "r", "--endpoint", "3", "--animation", "gif")
    ep = summary["contraction_endpoint"]
    assert ep["frame"] == 3 and ep["source"] == "given" and ep["detected_frame"] == 5
    assert (tmp_path / "r" / "figures" / "strain_animation.gif").is_file()
    assert (tmp_path / "r" / "figures" / "violins_frame0003.png").is_file()
    assert json.loads((tmp_path / "r" / "statistics.json").read_text())["frame"] == 3


def test_no_animation(small_case, tmp_path):
    _analyze(small_case, tmp_path / "r", "--animation", "none")
    assert not list((tmp_path / "r" / "figures").glob("strain_animation.*"))
    assert (tmp_path / "r" / "report.html").is_file()


def _hold_field(endpoint=7, n_frames=12):
    ref = np.array([[x, y] for y in range(5) for x in range(5)], float) * 20
    pos = []
    for k in range(n_frames):
        s = min(k / endpoint, 1.0)
        pos.append(ref @ np.diag([1 - 0.2 * s, 1 - 0.1 * s]))
    return compute_strain(ref, np.array(pos), grid_triangles(5, 5))


def test_endpoint_is_found_where_the_contraction_holds():
    field = _hold_field(endpoint=7)
    ep = endpoint_of(field)
    assert ep["frame"] == 7 and ep["source"] == "detected"
    times = np.arange(12) * 0.5
    ep = endpoint_of(field, times=times)
    assert ep["frame"] == 7 and ep["time"] == pytest.approx(3.5)
    assert endpoint_of(field, frame=11)["frame"] == 11
    for frame in (12, -1):  # frames count from the reference, never from the end
        with pytest.raises(InputError, match="outside"):
            endpoint_of(field, frame=frame)


def test_figure_formats_are_checked():
    assert parse_formats("svg") == ("png", "svg")
    assert parse_formats("PDF, png") == ("png", "pdf")
    with pytest.raises(InputError, match="unknown figure format"):
        parse_formats("tiff")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--endpoint", "9"], "outside the frames"),
        (["--maps-at", "1,x"], "comma-separated frame numbers"),
        (["--maps-at", "40"], "outside the frames"),
        (["--figure-format", "bmp"], "unknown figure format"),
        (["--endpoint-tolerance", "2"], "between 0 and 1"),
    ],
)
def test_bad_report_options_exit_2(small_case, tmp_path, capsys, extra, message):
    folder, _ = small_case
    argv = ["-q", "analyze", str(folder / "eq.avi"), "--grid", "3x3", "--out", str(tmp_path / "o")]
    assert main([*argv, *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.xdist_group("strain2d_report_run")  # run_dir made once, on one worker
def test_study_of_runs_writes_report_tables_and_figures(run_dir, small_case, tmp_path, capsys):
    out, _ = run_dir
    other = tmp_path / "run2"
    _analyze(small_case, other, "--endpoint", "4", "--animation", "none")
    study = tmp_path / "study"
    assert main(["study", str(out), str(other), "--out", str(study)]) == 0
    printed = capsys.readouterr().out
    assert "all specimens (2 specimens)" in printed
    for name in ("report.html", "summary.json", "statistics.json", "specimens.csv",
                 "figures/study_curves.png", "figures/study_violins.png",
                 "figures/specimen_means.png"):  # fmt: skip
        assert (study / name).is_file(), name
    summary = json.loads((study / "summary.json").read_text())
    assert [s["endpoint"] for s in summary["specimens"]] == [5, 4]
    assert summary["inputs"]["runs"] == [str(out), str(other)]
    page = _parse(study / "report.html")
    assert page.links and all(link.startswith("data:") for link in page.links)
    assert "Mixed-effects model" in " ".join(page.text)
    # an existing study folder is not replaced without --overwrite
    assert main(["-q", "study", str(out), "--out", str(study)]) == 2


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda d: (d / "summary.json").unlink(), "summary.json is missing"),
        (lambda d: (d / "strain_nodes.csv").write_text("frame,point\n0,0\n"), "lacks the columns"),
        (lambda d: (d / "summary.json").write_text("{"), "cannot be read"),
    ],
)
@pytest.mark.xdist_group("strain2d_report_run")
def test_study_of_a_corrupt_run_exits_2(run_dir, tmp_path, capsys, damage, message):
    import shutil

    out, _ = run_dir
    broken = tmp_path / "broken"
    shutil.copytree(out, broken)
    damage(broken)
    capsys.readouterr()
    assert main(["-q", "study", str(out), str(broken), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err, err
    assert not (tmp_path / "s").exists()


@pytest.mark.xdist_group("strain2d_report_run")  # run_dir made once, on one worker
def test_study_argument_errors_exit_2(run_dir, tmp_path, capsys):
    out, _ = run_dir
    cases = [
        ([], "give the run folders"),
        ([str(out), "--manifest", str(tmp_path / "m.csv")], "not both"),
        ([str(out), "--compare", "Exx"], "two components"),
        ([str(out), "--compare", "Exx,Ezz"], "unknown component"),
        (["--manifest", str(tmp_path / "none.csv")], "does not exist"),
        ([str(tmp_path / "no_run")], "does not exist"),
    ]
    for argv, message in cases:
        capsys.readouterr()
        assert main(["-q", "study", *argv, "--out", str(tmp_path / "s")]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, (argv, err)


@pytest.fixture(scope="module")
def tracked_study(tmp_path_factory):
    """A synthetic study (2 groups of 4 specimens) tracked with klt and combined with `study`."""
    import csv

    from sample_data_synth.specimens import Group, make_study

    root = tmp_path_factory.mktemp("tracked") / "data"
    design = (Group("anisotropic", 4, lx=0.80, ly=0.92), Group("isotropic", 4, lx=0.86, ly=0.86))
    truth = make_study(root, design=design, size=192, n_frames=12, rng=5)
    with open(root / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        argv = [
            "-q", "analyze", str(root / r["video"]), "--grid", "7x7", "--roi", r["roi"],
            "--tracker", "klt", "--window", "21", "--animation", "none",
            "--out", str(root / r["run"]),
        ]  # fmt: skip
        assert main(argv) == 0
    out = root.parent / "study"
    assert main(["-q", "study", "--manifest", str(root / "manifest.csv"), "--out", str(out)]) == 0
    return rows, truth, json.loads((out / "statistics.json").read_text()), out


@pytest.mark.xdist_group("strain2d_tracked_study")  # made once, on one worker
def test_study_gets_the_known_answer(tracked_study):
    """Significant in the group built with Exx != Eyy, not in the group built without."""
    _, truth, stats, _ = tracked_study
    by_name = {s["specimen"]: s for s in truth["specimens"]}
    for r in stats["specimens"]:
        exact = by_name[r["specimen"]]
        # the run's detected endpoint is the synthetic one, and the means are the exact ones
        assert r["endpoint"] == exact["endpoint"] and r["endpoint_source"] == "detected"
        assert abs(r["mean_Exx"] - exact["Exx"]) < STUDY_TRACKED_MEAN_STRAIN
        assert abs(r["mean_Eyy"] - exact["Eyy"]) < STUDY_TRACKED_MEAN_STRAIN
    for group in ("anisotropic", "isotropic"):
        expected = truth["groups"][group]["expected"]
        measured = stats["specimen_level"][group]
        significant = measured["t_p"] < 0.05
        assert significant == (expected == "Exx differs from Eyy"), (group, measured["t_p"])
        # the same verdict as the paired test on the exact specimen means
        assert significant == (truth["groups"][group]["exact_paired_t"]["p"] < 0.05)
    assert stats["specimen_level"]["anisotropic"]["mean_difference"] < -0.05
    effects = {e["term"]: e for e in stats["mixed_model"]["effects"]}
    assert effects["mean difference, anisotropic"]["t_p"] < 0.05
    assert effects["mean difference, isotropic"]["t_p"] > 0.05


@pytest.mark.xdist_group("strain2d_tracked_study")  # made once, on one worker
def test_tracked_study_report(tracked_study):
    *_, out = tracked_study
    page = _parse(out / "report.html")
    text = " ".join(page.text)
    assert "group anisotropic (4 specimens)" in text and "group isotropic (4 specimens)" in text
    assert "not significant" in text and "Exx is lower than Eyy: Exx shortens more" in text
    with open(out / "specimens.csv", newline="") as f:
        import csv

        rows = list(csv.DictReader(f))
    assert [r["specimen"] for r in rows] == [f"S{i:02d}" for i in range(1, 9)]


def test_lost_data_is_not_taken_for_a_finished_contraction():
    """Points lost from frame 5: the strain after it is unknown, not 'still'."""
    ref = np.array([[x, y] for y in range(5) for x in range(5)], float) * 20
    pos = np.array([ref @ np.diag([1 - 0.02 * k, 1 - 0.01 * k]) for k in range(12)])
    visible = np.ones((12, 25), bool)
    visible[5:] = False
    field = compute_strain(ref, pos, grid_triangles(5, 5), visible=visible)
    ep = endpoint_of(field)
    assert ep["frame"] == 4 and ep["source"].startswith("not reached")
    assert "unknown after frame 4" in ep["source"]
    # a contraction still going at the last frame is not called detected either
    field = compute_strain(ref, pos, grid_triangles(5, 5))
    ep = endpoint_of(field)
    assert ep["frame"] == 11 and ep["source"] == "not reached: still deforming at the last frame"


def test_run_outputs_survive_an_endpoint_without_nodes(tmp_path):
    from strain2d.report import run_outputs, write_run_report
    from strain2d.tracks import Tracks

    ref = np.array([[x, y] for y in range(5) for x in range(5)], float) * 20 + 20
    pos = np.array([ref @ np.diag([1 - 0.02 * k, 1 - 0.01 * k]) for k in range(8)])
    visible = np.ones((8, 25), bool)
    visible[6:] = False
    field = compute_strain(ref, pos, grid_triangles(5, 5), visible=visible)
    tracks = Tracks(pos, visible, visible.astype(float))
    frames = np.random.default_rng(0).uniform(0, 255, (8, 140, 140)).astype(np.uint8)
    extra = run_outputs(
        tmp_path, field, tracks, frames=lambda: iter(frames), times=np.arange(8.0),
        time_unit="frame", endpoint=7, animation="none", n_boot=50,
    )  # fmt: skip
    paired = extra["statistics"]["paired"]
    assert "error" in paired and "frame 7" in paired["error"]
    stats_text = (tmp_path / "statistics.json").read_text()
    json.loads(stats_text, parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
    write_run_report(tmp_path, {"software": {}, **extra})
    assert "Not computed" in (tmp_path / "report.html").read_text()


@pytest.mark.xdist_group("strain2d_report_run")  # run_dir made once, on one worker
def test_study_output_inside_a_run_folder_is_refused(run_dir, tmp_path, capsys):
    out, _ = run_dir
    capsys.readouterr()
    assert main(["-q", "study", str(out), "--out", str(out / "study")]) == 2
    assert "inside the input folder" in capsys.readouterr().err
    assert not (out / "study").exists()


def test_the_endpoint_is_named_by_the_tissue_not_by_a_trackers_noise():
    """A shortening along x with noise of either sign along y is a contraction (whichever
    tracker's noise it is); both axes moving, each its own way, is a deformation."""
    from strain2d.report import _deformation_kind

    kinds = [
        _deformation_kind(np.array(m), ("Exx", "Eyy", "Exy"))
        for m in ([-0.008, 0.0003, 0.001], [-0.008, -0.0003, 0.0], [0.01, -0.0015, 0.0],
                  [-0.008, 0.004, 0.0], [1e-6, -1e-6, 0.0], [-0.02, -0.01, 0.0])
    ]  # fmt: skip
    assert kinds == ["contraction", "contraction", "stretch", "deformation", "deformation",
                     "contraction"]  # fmt: skip


def test_renewed_references_are_flagged_with_the_point_renewed_most():
    from strain2d.report import _run_flags

    quality = {
        "lowest_visible_pct": 100, "lowest_coverage_pct": 100, "lowest_median_quality": 0.95,
        "mesh": {"slivers": 0, "n_triangles": 8},
    }  # fmt: skip
    ep = {"source": "detected"}
    assert _run_flags(quality, ep, None, {}, 0.0, [0, 0, 0]) == []
    (flag,) = _run_flags(quality, ep, None, {}, 0.0, [0, 3, 20, 0, 1])
    assert "of 3 of 5 points were renewed" in flag and "point 2, 20 times" in flag

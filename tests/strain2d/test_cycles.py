"""Repeated contractions: cycles found in a rendered sheet that twitches three times, against
its exact truth; a single contraction keeps today's endpoint."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from strain2d.cli import main
from strain2d.cycles import cycle_statistics, detect_cycles
from surface_strain import compute_strain, grid_triangles, nodal_scalars

COMPONENTS = ("Exx", "Eyy", "Exy")


@pytest.fixture(scope="module")
def twitching(tmp_path_factory):
    """The repeated-twitch case as a video, its stimulus CSV and mask PNG, and a dic run."""
    import cv2

    from sample_data_synth import write_video
    from sample_data_synth.twitches import make_repeated_twitches

    folder = tmp_path_factory.mktemp("twitches")
    case = make_repeated_twitches()
    write_video(case.video.frames, folder / "sheet.avi")
    (folder / "stimulus.csv").write_text(case.stimulus_csv())
    cv2.imwrite(str(folder / "mask.png"), case.mask.astype(np.uint8) * 255)
    argv = ["-q", "analyze", str(folder / "sheet.avi"), "--grid", "9x7", "--tracker", "dic",
            "--fps", "10", "--animation", "none", "--out", str(folder / "run")]  # fmt: skip
    assert main(argv) == 0
    return folder, case


def _true_curves(case, points):
    """The mean nodal strains the run would measure if it tracked every point exactly: the
    true positions on the run's own mesh (cell by cell, alternating diagonals)."""
    truth = case.video.truth
    positions = truth.positions(points)
    field = compute_strain(points, positions, grid_triangles(7, 9))
    node = nodal_scalars(field)
    return np.column_stack([np.nanmean(node[c], axis=1) for c in COMPONENTS])


@pytest.mark.xdist_group("strain2d_twitching")  # the dic run made once, on one worker
def test_every_cycle_of_a_repeated_contraction_is_found_with_its_peak_strains(twitching):
    folder, case = twitching
    summary = json.loads((folder / "run" / "summary.json").read_text())
    cycles = summary["cycles"]
    truth = case.video.truth.time_profile.cycles
    assert [c["cycle"] for c in cycles["cycles"]] == [1, 2, 3]
    for found, true in zip(cycles["cycles"], truth, strict=True):
        assert abs(found["onset"] - true["onset"]) <= 1 and abs(found["peak"] - true["peak"]) <= 1
        assert found["end"] is not None and abs(found["end"] - true["end"]) <= 1
    assert cycles["component"] == "Exx" and cycles["sign"] == -1.0  # a contraction along x
    # the endpoint is the peak of the largest cycle
    ep = summary["contraction_endpoint"]
    assert ep["frame"] == truth[0]["peak"] and ep["cycle"] == 1 and ep["source"] == "cycle"
    assert ep["label"] == "peak of cycle 1 of 3"
    # peak strains: the truth on the run's mesh, within 0.001
    from strain2d.tracks import read_tracks

    points = read_tracks(folder / "run" / "tracks.csv").reference
    true = _true_curves(case, points)
    for found, t in zip(cycles["cycles"], truth, strict=True):
        for k, name in enumerate(COMPONENTS):
            assert found["peak_mean"][name] == pytest.approx(true[t["peak"], k], abs=1e-3)
    # the sizes of the twitches: 1, 0.55 and 0.8 of the largest
    rise = np.array([c["amplitude"] for c in cycles["cycles"]])
    assert rise / rise[0] == pytest.approx([1.0, 0.55, 0.8], abs=0.02)
    # the ensemble: the true curves aligned at the true onsets, averaged, within 0.001
    ens = cycles["ensemble"]
    assert ens["n_cycles"] == 3
    n = len(ens["frames_since_onset"])
    ideal = np.nanmean([true[t["onset"] : t["onset"] + n] for t in truth], axis=0)
    for k, name in enumerate(COMPONENTS):
        assert np.asarray(ens["mean"][name]) == pytest.approx(ideal[:, k], abs=1e-3)
    # the tables: a row per cycle; each peak's strains per node
    with open(folder / "run" / "cycles.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["peak"]) for r in rows] == [c["peak"] for c in cycles["cycles"]]
    assert float(rows[0]["time_to_peak"]) == pytest.approx(0.5, abs=0.1)  # 5 frames at 10 fps
    with open(folder / "run" / "cycles_nodes.csv", newline="") as f:
        nodes = list(csv.DictReader(f))
    assert len(nodes) == 3 * 63 and {int(r["cycle"]) for r in nodes} == {1, 2, 3}
    assert "figures/cycles.png" in summary["outputs"]
    report = (folder / "run" / "report.html").read_text()
    assert "peak of cycle 1 of 3" in report


@pytest.mark.xdist_group("strain2d_twitching")  # the dic run made once, on one worker
def test_the_cycles_are_cut_at_the_pulses_of_a_stimulus(twitching):
    """From the stimulus recorded beside the video: the same cycles, each with its pulse; a
    pulse with no contraction after it is reported as such."""
    _, case = twitching
    truth = case.video.truth
    true = _true_curves(case, truth.grid((9, 7)))
    found = detect_cycles(true, COMPONENTS, stimulus=case.stimulus)
    assert found["trigger"] == "stimulus"
    got = [(c.onset, c.peak, c.stimulus) for c in found["cycles"]]
    assert got == [(t["onset"], t["peak"], t["onset"] - 1) for t in truth.time_profile.cycles]
    silent = case.stimulus.copy()
    silent[46] = 1.0  # a last pulse the tissue does not answer
    last = detect_cycles(true, COMPONENTS, stimulus=silent)["cycles"][-1]
    assert last.onset == 46 and last.peak is None and last.stimulus == 46


def test_noise_alone_and_a_single_contraction_make_no_repeated_cycles(small_case, tmp_path):
    rng = np.random.default_rng(0)
    flat = rng.normal(0, 1e-4, (40, 3))
    assert detect_cycles(flat, COMPONENTS)["cycles"] == [] or all(
        c.amplitude < 1e-3 for c in detect_cycles(flat, COMPONENTS)["cycles"]
    )
    one = np.zeros((30, 3))
    one[5:20, 0] = -0.05 * np.sin(np.linspace(0, np.pi, 15))
    found = detect_cycles(one + rng.normal(0, 2e-4, one.shape), COMPONENTS)
    assert len(found["cycles"]) == 1
    stats = cycle_statistics(found, one, COMPONENTS, np.arange(30) / 10)
    assert stats["largest"] == 0 and stats["ensemble"]["n_cycles"] == 1
    # a run of one contraction (the paper's ramp): one cycle, the endpoint found as before,
    # the same as without the cycles (the endpoint a run with cycles turned off would get)
    from strain2d.report import endpoint_of

    folder, _ = small_case
    argv = ["-q", "analyze", str(folder / "eq.avi"), "--grid", "4x4", "--tracker", "dic",
            "--animation", "none", "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert len(summary["cycles"]["cycles"]) == 1 and not summary["cycles"]["repeated"]
    ep = summary["contraction_endpoint"]
    assert ep["source"] != "cycle" and "cycle" not in ep
    from strain2d.pipeline import strain_from_tracks
    from strain2d.tracks import read_tracks

    field = strain_from_tracks(read_tracks(tmp_path / "run" / "tracks.csv"), grid_shape=(4, 4))
    assert ep["frame"] == endpoint_of(field)["frame"]
    assert (tmp_path / "run" / "cycles.csv").exists()
    assert not (tmp_path / "run" / "figures" / "cycles.png").exists()
    assert main([*argv[:-1], str(tmp_path / "r2"), "--cycle", "2"]) == 2


@pytest.mark.xdist_group("strain2d_twitching")  # the dic run made once, on one worker
def test_another_cycle_can_be_the_endpoint_and_every_peak_can_get_maps(twitching, tmp_path):
    folder, _ = twitching
    argv = ["-q", "analyze", str(folder / "sheet.avi"), "--grid", "5x4", "--tracker", "dic",
            "--fps", "10", "--animation", "none", "--cycle", "2", "--maps-at", "peaks,40",
            "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    ep = summary["contraction_endpoint"]
    assert ep["cycle"] == 2 and ep["frame"] == summary["cycles"]["cycles"][1]["peak"]
    maps = sorted(p.name for p in (tmp_path / "run" / "figures").glob("strain_frame*.png"))
    peaks = [c["peak"] for c in summary["cycles"]["cycles"]]
    assert maps == sorted({f"strain_frame{k:04d}.png" for k in [*peaks, 40, 47]})
    captions = {f["files"][0]: f["caption"] for f in summary["figures"]}
    assert "the peak of cycle 3" in captions[f"figures/strain_frame{peaks[2]:04d}.png"]
    assert "peak of cycle 2 of 3" in captions[f"figures/strain_frame{peaks[1]:04d}.png"]
    assert main([*argv[:-1], str(tmp_path / "r4"), "--cycle", "4"]) == 2


@pytest.mark.xdist_group("strain2d_twitching")  # the dic run made once, on one worker
def test_signals_beside_the_video_are_aligned_to_the_frames_with_their_lag(twitching, tmp_path):
    """A force channel sampled at 100 Hz that follows the contraction 0.3 s late and a
    stimulus of 5 ms pulses, by time: per frame the force is the true strain 3 frames
    before, the pulses are on the frames before the onsets, and the stimulus cuts the
    cycles; by frame number, the same values."""
    folder, case = twitching
    from strain2d.tracks import read_tracks

    points = read_tracks(folder / "run" / "tracks.csv").reference
    true = _true_curves(case, points)[:, 0]  # mean Exx per frame
    t = np.arange(0, 4.8, 0.01)
    lag = 0.3
    force = -1000 * np.interp(t - lag, np.arange(48) / 10, true, left=0.0)
    pulse_times = [(c["onset"] - 1) / 10 for c in case.video.truth.time_profile.cycles]
    stimulus = np.zeros_like(t)
    for p in pulse_times:
        stimulus[(t >= p - 0.0025) & (t < p + 0.0025)] = 1  # one 5 ms sample: under a frame
    lines = ["time_ms,force_mN,stimulus"] + [
        f"{1000 * a:.1f},{b:.6f},{int(c)}" for a, b, c in zip(t, force, stimulus, strict=True)
    ]
    (tmp_path / "daq.csv").write_text("\n".join(lines) + "\n")
    argv = ["-q", "analyze", str(folder / "sheet.avi"), "--grid", "9x7", "--tracker", "dic",
            "--fps", "10", "--animation", "none", "--signals", str(tmp_path / "daq.csv"),
            "--trigger", "stimulus", "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 0
    with open(tmp_path / "run" / "signals.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["frame", "time_s", "force_mN", "stimulus", "Exx_mean", "Eyy_mean",
                             "Exy_mean"]  # fmt: skip
    got = np.array([float(r["force_mN"]) for r in rows])
    expected = -1000 * np.r_[np.zeros(3), true[:-3]]
    assert got == pytest.approx(expected, abs=0.03 * np.abs(expected).max())
    # the lag, read back from the table: the force trails the measured strain by 3 frames
    strain = np.array([float(r["Exx_mean"]) for r in rows])
    shifts = range(-6, 7)
    score = [np.corrcoef(np.roll(strain, s)[6:-6], -got[6:-6])[0, 1] for s in shifts]
    assert list(shifts)[int(np.argmax(score))] == 3
    pulses = [int(r["frame"]) for r in rows if float(r["stimulus"]) == 1]
    assert pulses == [c["onset"] - 1 for c in case.video.truth.time_profile.cycles]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["signals"]["aligned_by"] == "time" and summary["signals"]["samples"] == 480
    assert summary["cycles"]["trigger"] == "stimulus"
    assert [c["stimulus"] for c in summary["cycles"]["cycles"]] == pulses
    assert "figures/strain_and_signals.png" in summary["outputs"]
    report = (tmp_path / "run" / "report.html").read_text()
    assert "Repeated contractions" in report and "at the pulses of the stimulus" in report
    assert "Signals beside the video" in report and "force_mN" in report
    # the same by the video's frame numbers, here with --start 2: the run's frame k is
    # the video's frame k + 2
    frames = ["frame,force_mN"] + [f"{k},{v:.6f}" for k, v in enumerate(expected)]
    (tmp_path / "byframe.csv").write_text("\n".join(frames) + "\n")
    from strain2d.signals import read_signals

    aligned = read_signals(tmp_path / "byframe.csv", 46, start=2)
    assert aligned.values[:, 0] == pytest.approx(expected[2:], abs=1e-6)
    assert aligned.aligned_by == "frame"


@pytest.mark.parametrize(
    ("text", "extra", "fragments"),
    [
        ("force\n1\n2\n", [], ["needs a frame column", "time_ms"]),
        ("time_s,force\n0,1\n0.1,2\n", ["--no-fps"], ["--fps"]),
        ("frame\n0\n1\n", [], ["no signal"]),
        ("frame,force\n0,1\n1,one\n", [], ["line 3", "force must be a number"]),
        ("frame,force\n0,1\n0,2\n", [], ["line 3", "go forward"]),
        ("frame,force\n100,1\n101,2\n", [], ["covers frames 100-101", "none of the run's"]),
        ("frame,force\n0,1,2\n", [], ["line 2", "3 cells"]),
        ("frame,force\n0,1\n1,2\n", ["--trigger", "stimulus"], ["--trigger stimulus", "force"]),
        ("frame,force\n0,1e308\n1,-1e308\n", [], ["line 2", "beyond what a measurement"]),
        ("frame,force\n0,inf\n1,2\n", [], ["line 2", "beyond what a measurement"]),
        ("frame,force,force\n0,1,2\n1,2,3\n", [], ["force is there twice"]),
        ("frame,force\n0,\n1,nan\n", [], ["holds no value"]),
        ("frame,stimulus\n0,0\n1,0\n2,0\n", ["--trigger", "stimulus"], ["no pulse"]),
    ],
)
def test_bad_signals_are_one_line_before_the_tracking(small_case, tmp_path, capsys, text, extra,
                                                      fragments):  # fmt: skip
    folder, _ = small_case
    (tmp_path / "s.csv").write_text(text)
    fps = [] if "--no-fps" in extra else ["--fps", "5"]
    extra = [e for e in extra if e != "--no-fps"]
    argv = ["-q", "analyze", str(folder / "eq.avi"), "--grid", "3x3", *fps, "--signals",
            str(tmp_path / "s.csv"), *extra, "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tracking" not in err[0], err
    for fragment in fragments:
        assert fragment in err[0], err[0]
    assert not (tmp_path / "run").exists()


def test_a_study_of_repeated_contractions_reports_each_cycle_and_each_specimen(tmp_path):
    """Three specimens, each twitching three times with its own sizes: the study lists every
    cycle, averages each specimen's cycles, and tests Exx against Eyy per cycle number and
    on the averages, with the specimen as the unit."""
    from sample_data_synth import write_video
    from sample_data_synth.twitches import make_repeated_twitches

    sizes = [(1.0, 0.55, 0.8), (0.7, 1.0, 0.6), (0.9, 0.8, 1.0)]
    runs = []
    for n, (x, y, z) in enumerate(sizes):
        twitches = ((3, 8, 15, x), (18, 22, 29, y), (32, 37, 44, z))
        case = make_repeated_twitches(shape=(120, 160), twitches=twitches, rng=n)
        write_video(case.video.frames, tmp_path / f"S{n}.avi")
        argv = ["-q", "analyze", str(tmp_path / f"S{n}.avi"), "--grid", "5x4", "--tracker",
                "dic", "--fps", "10", "--animation", "none",
                "--out", str(tmp_path / f"S{n}")]  # fmt: skip
        assert main(argv) == 0
        runs.append(tmp_path / f"S{n}")
    assert main(["-q", "study", *map(str, runs), "--out", str(tmp_path / "study")]) == 0
    stats = json.loads((tmp_path / "study" / "statistics.json").read_text())
    cycles = stats["cycles"]
    assert len(cycles["rows"]) == 9 and [e["n_cycles"] for e in cycles["specimens"]] == [3, 3, 3]
    # each row is its run's cycle, and each specimen's average is the mean of its rows
    for run, entry in zip(runs, cycles["specimens"], strict=True):
        mine = json.loads((run / "summary.json").read_text())["cycles"]["cycles"]
        rows = [r for r in cycles["rows"] if r["specimen"] == entry["specimen"]]
        assert [r["Exx"] for r in rows] == pytest.approx([c["peak_mean"]["Exx"] for c in mine])
        assert entry["Exx_mean"] == pytest.approx(np.mean([r["Exx"] for r in rows]))
        assert entry["Exx_sd"] == pytest.approx(np.std([r["Exx"] for r in rows], ddof=1))
        # the sizes of this specimen's twitches, read back
        assert np.array([r["Exx"] for r in rows]) / min(r["Exx"] for r in rows) == (
            pytest.approx(np.array(sizes[runs.index(run)]) / max(sizes[runs.index(run)]),
                          abs=0.05))  # fmt: skip
    assert [t["cycle"] for t in cycles["per_cycle"]] == [1, 2, 3]
    assert all(t["n"] == 3 and t["mean_difference"] < 0 for t in cycles["per_cycle"])
    assert cycles["averaged_over_cycles"]["n"] == 3
    with open(tmp_path / "study" / "cycles.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 9
    with open(tmp_path / "study" / "specimen_cycles.csv", newline="") as f:
        assert [r["n_cycles"] for r in csv.DictReader(f)] == ["3", "3", "3"]
    assert "Repeated contractions" in (tmp_path / "study" / "report.html").read_text()


def test_peaks_are_found_by_prominence_as_scipy_finds_them():
    """The cycles' peak finder against scipy.signal.find_peaks (which the runs do not import:
    it takes longer to load than the cycles take to find), flat tops included."""
    from scipy.signal import find_peaks

    from surface_strain.cycles import _prominent_peaks

    rng = np.random.default_rng(7)
    for trial in range(500):
        n = int(rng.integers(3, 80))
        a = rng.normal(0, 1, n)
        if trial % 2:
            a = np.round(a.cumsum(), 1)  # steps of 0.1: flat tops and valleys
        least = float(rng.uniform(0, 2))
        assert np.array_equal(_prominent_peaks(a, least), find_peaks(a, prominence=least)[0])


@pytest.mark.xdist_group("strain2d_twitching")  # the dic run made once, on one worker
def test_signals_with_every_other_frame_keep_their_pulses_and_the_time_axis_its_step(
    twitching, tmp_path
):
    """--step 2: a run frame stands for two of the video's, so a pulse on a frame left out is
    kept (by frame number and by time), and the run's time axis is 2 / fps per frame."""
    from strain2d.signals import read_signals

    folder, case = twitching
    onsets = [c["onset"] for c in case.video.truth.time_profile.cycles]
    pulses = [o - 1 for o in onsets]  # 2, 17, 31: an odd one is between the frames used
    by_frame = tmp_path / "f.csv"
    by_frame.write_text("frame,stimulus,T\n" + "".join(
        f"{k},{int(k in pulses)},{20 + k}\n" for k in range(48)))  # fmt: skip
    aligned = read_signals(by_frame, 24, step=2)
    assert aligned.names == ["stimulus", "T"]  # a column named T is a signal, not the time
    assert sorted(np.flatnonzero(aligned.column("stimulus") == 1)) == [1, 9, 16]
    by_time = tmp_path / "t.csv"
    by_time.write_text("time_s,stimulus\n" + "".join(
        f"{k / 100:.2f},{int(round(k / 10) in pulses and k % 10 == 0)}\n"
        for k in range(480)))  # fmt: skip
    aligned = read_signals(by_time, 24, fps=10, step=2)
    assert sorted(np.flatnonzero(aligned.column("stimulus") == 1)) == [1, 9, 16]
    argv = ["-q", "analyze", str(folder / "sheet.avi"), "--grid", "5x4", "--tracker", "dic",
            "--fps", "10", "--step", "2", "--animation", "none", "--signals", str(by_frame),
            "--trigger", "stimulus", "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["time_axis"] == {"fps": 10, "unit": "s", "step": 2}
    cycles = summary["cycles"]["cycles"]
    assert len(cycles) == 3 and summary["cycles"]["repeated"]
    for c in cycles:  # times of the video: run frame k is video frame 2 k, at 0.2 k s
        assert c["peak_time"] == pytest.approx(0.2 * c["peak"])
    with open(tmp_path / "run" / "signals.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert float(rows[5]["time_s"]) == pytest.approx(1.0)

"""Batches of runs: in one process, on a Dask scheduler with worker processes, and their faults.

The cluster here is what a lab starts by hand: ``dask scheduler`` and two
``dask worker`` processes on the loopback address, each worker one process
with one thread.  One worker is killed while it runs a specimen and one video
is corrupt: the killed worker's run is made again on the other worker, the
corrupt video is reported in one line, every other run completes, and the
results equal those of the same batch run in one process.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.badinput import assert_no_process_left
from tissue_core.batch import Job, differences, job_state
from tissue_core.outputs import foreign_content, read_marker

#: the module's tests share its batches: one xdist worker runs them all (make test: loadgroup)
pytestmark = pytest.mark.xdist_group("batch")

RUN_OPTIONS = ["--grid", "3x3", "--animation", "none", "--tracker", "klt"]


def _cli(*argv: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", *argv], capture_output=True, text=True, errors="replace",
        timeout=300, cwd=cwd,
    )  # fmt: skip


@pytest.fixture(scope="module")
def study_data(tmp_path_factory) -> Path:
    """Four small specimen videos and a truncated fifth, in a manifest with their ROI."""
    root = tmp_path_factory.mktemp("batch")
    data = root / "data"
    done = _cli("sample_data_synth", "-q", "study", "--size", "96", "--frames", "6",
                "--per-group", "2", "--out", str(data))  # fmt: skip
    assert done.returncode == 0, done.stderr
    whole = (data / "S04.avi").read_bytes()  # a copy cut short: frames 3 on cannot be decoded
    (data / "S05.avi").write_bytes(whole[: int(len(whole) * 0.6)])
    with open(data / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    rows.append({**rows[-1], "specimen": "S05", "video": "S05.avi", "run": "runs/S05"})
    with open(data / "manifest.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return data


@pytest.fixture(scope="module")
def sequential(study_data) -> tuple[Path, subprocess.CompletedProcess]:
    """The batch run in one process, one specimen after the other."""
    out = study_data.parent / "sequential"
    done = _cli("strain2d", "batch", str(study_data / "manifest.csv"), "--workers", "1",
                "--out", str(out), *RUN_OPTIONS)  # fmt: skip
    return out, done


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for(predicate, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _workers(address: str) -> int:
    from distributed import Client

    with Client(address, timeout="10s") as client:
        return len(client.scheduler_info(n_workers=-1)["workers"])


def test_a_failing_video_is_reported_and_the_others_complete(sequential):
    out, done = sequential
    assert done.returncode == 2, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("strain2d batch: error: 1 of 5 runs failed"), last
    assert "S05:" in last and "Traceback" not in done.stderr
    record = json.loads((out / "batch.json").read_text())
    status = {r["name"]: r["status"] for r in record["runs"]}
    assert status == {"S01": "done", "S02": "done", "S03": "done", "S04": "done", "S05": "failed"}
    assert not (out / "runs" / "S05").exists()
    for name in ("S01", "S02", "S03", "S04"):
        assert (out / "runs" / name / "strain_nodes.csv").is_file()
    # the study has the four specimens that were analyzed
    study = json.loads((out / "study" / "summary.json").read_text())
    assert [s["specimen"] for s in study["specimens"]] == ["S01", "S02", "S03", "S04"]
    log = (out / "batch.log").read_text()
    assert "S05: failed:" in log and "[5/5]" in log


def test_a_batch_on_a_scheduler_with_a_killed_worker_equals_the_sequential_one(
    study_data, sequential, tmp_path
):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = []
    env = dict(os.environ)
    try:
        scheduler = subprocess.Popen(
            [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
             str(port), "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
        )  # fmt: skip
        procs.append(scheduler)
        worker = [sys.executable, "-m", "dask", "worker", address, "--host", "127.0.0.1",
                  "--nthreads", "1", "--no-nanny", "--no-dashboard"]  # fmt: skip
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    worker, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
                )
            )
        _wait_for(lambda: _scheduler_up(address), "the scheduler and its two workers")
        out = tmp_path / "cluster"
        batch = subprocess.Popen(
            [sys.executable, "-m", "strain2d", "batch", str(study_data / "manifest.csv"),
             "--scheduler", address, "--out", str(out), *RUN_OPTIONS],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace",
        )  # fmt: skip
        # both workers are busy once two runs are being written: kill one of them
        runs = out / "runs"
        _wait_for(
            lambda: batch.poll() is None and len(list(runs.glob(".S0*.tmp-*"))) >= 2,
            "two runs in progress",
            timeout=120,
        )
        procs[1].send_signal(signal.SIGKILL)
        _, stderr = batch.communicate(timeout=300)
    finally:
        for p in procs:
            p.kill()
            p.wait()
    assert batch.returncode == 2, stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("strain2d batch: error: 1 of 5 runs failed"), stderr
    record = json.loads((out / "batch.json").read_text())
    deaths = {r["name"]: r["worker_deaths"] for r in record["runs"]}
    assert sum(deaths.values()) >= 1, record  # the killed worker's run was made again
    assert "started again: its worker died" in (out / "batch.log").read_text()
    assert not list(runs.glob(".*.tmp-*")), "scratch of the killed run left behind"
    # the same results as the batch run in one process, study included
    seq, _ = sequential
    assert differences(seq, out) == []

    # a rerun makes only what is missing: a removed run and the failing one
    before = {p.name: (p / ".tissue-strain-result.json").read_bytes() for p in runs.iterdir()}
    study_made = (out / "study" / "summary.json").stat().st_mtime_ns
    shutil.rmtree(runs / "S02")
    rerun = _cli("strain2d", "batch", str(study_data / "manifest.csv"), "--workers", "1",
                 "--out", str(out), *RUN_OPTIONS)  # fmt: skip
    assert rerun.returncode == 2, rerun.stderr
    log = (out / "batch.log").read_text().splitlines()
    start = max(i for i, line in enumerate(log) if " batch of 5 runs: " in line)
    assert "3 complete already, 2 to run" in log[start], log[start]
    redone = [line for line in log[start:] if "] S0" in line and ": done in " in line]
    assert len(redone) == 1 and " S02: done in " in redone[0], log[start:]
    assert any(" study: done in " in line for line in log[start:]), log[start:]
    for name in ("S01", "S03", "S04"):  # untouched
        assert (runs / name / ".tissue-strain-result.json").read_bytes() == before[name]
    # a run was made again: the study is too (its manifest is the same)
    assert (out / "study" / "summary.json").stat().st_mtime_ns != study_made
    assert differences(seq / "runs", runs) == []


def _scheduler_up(address: str) -> bool:
    try:
        return _workers(address) == 2
    except (OSError, TimeoutError):
        return False


def _job(run: Path, source: Path, *extra: str) -> Job:
    argv = ("analyze", str(source), *RUN_OPTIONS, *extra, "--out", str(run))
    return Job(run.name, "strain2d.cli", argv, str(run), inputs=(str(source),))


def test_a_run_counts_as_complete_only_with_the_same_parameters_and_inputs(
    study_data, sequential, tmp_path
):
    seq, _ = sequential
    with open(study_data / "manifest.csv", newline="") as f:
        rows = {r["specimen"]: r for r in csv.DictReader(f)}
    video = tmp_path / "S01.avi"
    shutil.copy2(study_data / "S01.avi", video)
    run = tmp_path / "S01"
    shutil.copytree(seq / "runs" / "S01", run)
    recorded = json.loads((run / ".tissue-strain-result.json").read_text())["command"]
    roi = ["--roi", rows["S01"]["roi"]]
    job = Job("S01", "strain2d.cli", tuple(recorded[1:]), str(run), inputs=(recorded[2],))
    assert job_state(job) == "complete"
    assert job_state(_job(run, Path(recorded[2]), *roi, "--fps", "10")).endswith(
        "made with other parameters"
    )
    assert job_state(_job(tmp_path / "nothing", video)) == "missing"
    # an input changed since the run (same size, newer): read again and found different
    source = Path(recorded[2])
    other = Job("S01", "strain2d.cli", job.argv, str(run), inputs=(str(source),))
    data = bytearray(source.read_bytes())
    backup = tmp_path / "backup.avi"
    shutil.copy2(source, backup)
    try:
        data[-10] ^= 0xFF
        source.write_bytes(bytes(data))
        assert job_state(other).endswith("inputs that have changed since")
    finally:
        shutil.copy2(backup, source)
    # touched but the same content: still complete
    os.utime(source)
    assert job_state(other) == "complete"
    # a file of the run edited by hand
    with open(run / "tracks.csv", "a") as f:
        f.write("\n")
    assert job_state(job).endswith("was changed since it was written")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--workers", "0"], "--workers must be 1 or more, got 0"),
        (["--workers", "2", "--scheduler", "tcp://x:1"], "give --workers (a local cluster) or"),
        (["--grid"], "expected one argument"),
        (["--animation", "avi"], "invalid choice: 'avi'"),
    ],
)
def test_bad_batch_options_end_in_one_line(study_data, tmp_path, argv, message):
    done = _cli("strain2d", "batch", str(study_data / "manifest.csv"), "--out",
                str(tmp_path / "b"), *argv)  # fmt: skip
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 or "usage:" in done.stderr
    assert not (tmp_path / "b").exists()


def test_bad_manifests_end_in_one_line_before_anything_runs(study_data, tmp_path):
    def batch(text: str, *extra: str) -> subprocess.CompletedProcess:
        manifest = tmp_path / "m.csv"
        manifest.write_text(text)
        return _cli("strain2d", "batch", str(manifest), "--out", str(tmp_path / "b"), *extra)

    video = study_data / "S01.avi"
    cases = [
        ("specimen,group\nA,x\n", "needs a column 'video', one row per run"),
        (f"video,grid\n{video},7by7\n", None),  # analyze says what is wrong with it: a run fails
        (f"video,animation\n{video},avi\n", "line 2: column animation must be one of"),
        (f"video,fps\n{video},fast\n", "line 2: column fps takes a float, got 'fast'"),
        (f"video,specimen\n{video},A\n{video},A\n", "run names must be unique"),
        ("video\n", "has no rows"),
        (f"video,specimen\n{video},x/y\n", "cannot name a folder (it holds /)"),
        (f"video,specimen\n{video},.A.tmp-x\n", "line 2: specimen '.A.tmp-x' starts with '.'"),
        (f"video,specimen\n{video},S0?\n", "cannot name a folder (it holds ?)"),
        (f"video,specimen\n{video},A,extra\n", "line 2: 3 cells where the header has 2"),
        (f"video,specimen,group\n{video},A\n", "line 2: 2 cells where the header has 3"),
        (f"video,specimen\n{video},a\n{video},A\n", "run names must be unique"),
    ]
    for text, message in cases:
        done = batch(text, "--workers", "1", "--no-study", *RUN_OPTIONS)
        assert done.returncode == 2, (text, done.stderr)
        assert "Traceback" not in done.stderr
        line = done.stderr.strip().splitlines()[-1]
        if message is None:
            assert "1 of 1 runs failed" in line and "7by7" in line, line
            shutil.rmtree(tmp_path / "b")
        else:
            assert message in line, (text, line)
            assert not (tmp_path / "b").exists(), text  # refused before anything was made
    # a folder that is not a batch's is never used
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    done = _cli("strain2d", "batch", str(study_data / "manifest.csv"), "--out", str(folder))
    assert done.returncode == 2 and "is not a batch folder" in done.stderr
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]


def test_a_run_made_with_other_parameters_is_kept_without_overwrite(sequential, study_data):
    seq, _ = sequential
    before = (seq / "runs" / "S01" / ".tissue-strain-result.json").read_bytes()
    done = _cli("strain2d", "batch", str(study_data / "manifest.csv"), "--workers", "1",
                "--out", str(seq), "--grid", "4x4", "--animation", "none")  # fmt: skip
    assert done.returncode == 2
    assert "run S01: " in done.stderr and "made with other parameters (and 3 more)" in done.stderr
    assert "--overwrite makes them again" in done.stderr
    assert (seq / "runs" / "S01" / ".tissue-strain-result.json").read_bytes() == before


def test_ctrl_c_stops_a_batch_on_a_local_cluster_and_leaves_whole_runs_only(study_data, tmp_path):
    """Ctrl-C at a terminal reaches every process of the batch (its process group): the workers
    leave it to the batch, which stops them and names the runs there are, in one line."""
    out = tmp_path / "b"
    batch = subprocess.Popen(
        [sys.executable, "-m", "strain2d", "batch", str(study_data / "manifest.csv"),
         "--workers", "2", "--out", str(out), "--no-study", *RUN_OPTIONS],
        stderr=subprocess.PIPE, text=True, errors="replace", start_new_session=True,
    )  # fmt: skip
    runs = out / "runs"
    _wait_for(
        lambda: batch.poll() is None and any(runs.glob(".S0*.tmp-*")), "a run in progress", 120
    )
    os.killpg(batch.pid, signal.SIGINT)  # the whole group, as the terminal sends it
    _, stderr = batch.communicate(timeout=120)
    assert batch.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("strain2d batch: interrupted"), stderr
    # no worker goes on writing runs after the batch has ended: every process of the batch's
    # session (its cluster's workers too) ends, and only then are its runs looked at
    assert_no_process_left(batch.pid)
    assert not list(runs.glob(".*")), "scratch of an interrupted run left behind"
    made = sorted(runs.iterdir()) if runs.is_dir() else []
    for run in made:  # whole runs only, each with its marker
        assert read_marker(run) is not None and foreign_content(run) is None, run
    named = last.split("written to ")[1].split(", ") if "written to" in last else []
    assert sorted(named) == [str(run) for run in made], (last, made)  # the message is true
    assert "interrupted: " in (out / "batch.log").read_text()


def test_ctrl_c_stops_a_batch_in_one_process_after_the_run_it_was_making(study_data, tmp_path):
    out = tmp_path / "b"
    batch = subprocess.Popen(
        [sys.executable, "-m", "strain2d", "batch", str(study_data / "manifest.csv"),
         "--workers", "1", "--out", str(out), *RUN_OPTIONS],
        stderr=subprocess.PIPE, text=True, errors="replace",
    )  # fmt: skip
    runs = out / "runs"
    _wait_for(lambda: batch.poll() is None and (runs / "S01").is_dir(), "the first run", 120)
    _wait_for(lambda: batch.poll() is None and any(runs.glob(".S02.tmp-*")), "the second", 120)
    batch.send_signal(signal.SIGINT)
    _, stderr = batch.communicate(timeout=120)
    assert batch.returncode == 130, stderr
    last = stderr.strip().splitlines()[-1]
    assert last == f"strain2d batch: interrupted after the results were written to {runs / 'S01'}"
    assert sorted(p.name for p in runs.iterdir()) == ["S01"]  # no scratch, no other run
    record = json.loads((out / "batch.json").read_text())
    assert [(r["name"], r["status"]) for r in record["runs"]] == [("S01", "done")]
    assert "interrupted: 1 of 5 runs made" in (out / "batch.log").read_text()
    assert not (out / "study").exists()


def test_a_study_manifest_the_user_edited_is_kept_and_the_study_is_built_from_it(
    study_data, tmp_path, capsys
):
    """The batch rewrites its study manifest while it is its own; once edited it is the user's:
    kept byte for byte, the study built from it (again when it is edited again), the finished
    runs it leaves out named; --overwrite alone replaces it."""
    from strain2d.cli import main
    from tissue_core.outputs import written_here

    with open(study_data / "manifest.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["specimen"] in ("S01", "S03")]
    manifest = tmp_path / "two.csv"
    with open(manifest, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["video", "specimen", "group", "roi"])
        writer.writerows([study_data / r["video"], r["specimen"], r["group"], r["roi"]]
                         for r in rows)  # fmt: skip
    out = tmp_path / "b"
    batch = ["-q", "batch", str(manifest), "--workers", "1", "--out", str(out), *RUN_OPTIONS]
    path = out / "study_manifest.csv"

    def study() -> list[tuple[str, str]]:
        summary = json.loads((out / "study" / "summary.json").read_text())
        return [(s["specimen"], s["group"]) for s in summary["specimens"]]

    assert main(batch) == 0, capsys.readouterr().err
    assert written_here(path) and study() == [("S01", "anisotropic"), ("S03", "isotropic")]
    mine = "run,specimen,group,note\nruns/S01,S01,treated,checked by hand\n"
    path.write_text(mine)
    assert main(batch) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("strain2d batch: warning: "), err
    assert str(path) in err[0] and "kept as it is" in err[0]
    assert "does not list the finished runs S03" in err[0] and "--overwrite" in err[0]
    assert path.read_text() == mine and study() == [("S01", "treated")]
    marker = (out / "study" / ".tissue-strain-result.json").read_bytes()
    assert main(batch) == 0  # nothing changed: the study is kept
    assert (out / "study" / ".tissue-strain-result.json").read_bytes() == marker
    path.write_text(mine.replace("treated", "control"))  # edited again: the study is made again
    assert main(batch) == 0
    assert study() == [("S01", "control")]
    # a batch that fails before the study leaves the user's manifest as it is
    capsys.readouterr()
    assert main([*batch, "--grid", "4x4"]) == 2
    assert "made with other parameters" in capsys.readouterr().err
    assert path.read_text() == mine.replace("treated", "control")
    # --overwrite replaces it with the batch's list of the runs
    assert main([*batch, "--overwrite"]) == 0
    assert written_here(path) and "treated" not in path.read_text()
    assert study() == [("S01", "anisotropic"), ("S03", "isotropic")]


def test_a_manifest_gives_each_specimen_its_tissue_mask(study_data, tmp_path, capsys):
    """A ``mask`` column (relative to the manifest, as a video is): each run's grid fills its
    own specimen's mask, the mask is one of the run's inputs, and a mask that does not fit
    its video fails that specimen's run in one line naming it; the others complete."""
    import cv2
    import numpy as np

    from strain2d.cli import main
    from strain2d.tracks import read_tracks

    with open(study_data / "manifest.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["specimen"] in ("S01", "S02")]
    yy, xx = np.mgrid[:96, :96]
    left = (xx < 50) & (yy > 10) & (yy < 86) & (xx > 10)
    disc = (xx - 48) ** 2 + (yy - 48) ** 2 < 36**2
    (tmp_path / "masks").mkdir()
    cv2.imwrite(str(tmp_path / "masks" / "S01.png"), left.astype(np.uint8) * 255)
    cv2.imwrite(str(tmp_path / "masks" / "S02.png"), disc.astype(np.uint8) * 255)
    manifest = tmp_path / "masked.csv"
    with open(manifest, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["video", "specimen", "group", "mask"])
        writer.writerows([study_data / r["video"], r["specimen"], r["group"],
                          f"masks/{r['specimen']}.png"] for r in rows)  # fmt: skip
    out = tmp_path / "b"
    options = ["--workers", "1", "--grid", "5x5", "--animation", "none", "--tracker", "klt"]
    assert main(["-q", "batch", str(manifest), "--out", str(out), *options]) == 0, (
        capsys.readouterr().err
    )
    for name, tissue in (("S01", left), ("S02", disc)):
        run = out / "runs" / name
        ref = read_tracks(run / "tracks.csv").reference
        assert tissue[np.round(ref[:, 1]).astype(int), np.round(ref[:, 0]).astype(int)].all()
        summary = json.loads((run / "summary.json").read_text())
        assert summary["points"]["mask"]["file"] == str(tmp_path / "masks" / f"{name}.png")
        assert any(str(tmp_path / "masks" / f"{name}.png") in i for i in summary["command"])
    # the rectangle's grid is whole and spans it; the disc's corners are off the tissue
    s01 = read_tracks(out / "runs" / "S01" / "tracks.csv").reference
    assert len(s01) == 25 and s01.min(axis=0).tolist() == [11, 11]
    assert len(read_tracks(out / "runs" / "S02" / "tracks.csv").reference) < 25
    # a row whose mask does not fit its video: that run fails in one line, the other is made
    cv2.imwrite(str(tmp_path / "masks" / "S02.png"), np.full((40, 40), 255, np.uint8))
    capsys.readouterr()
    assert main(["-q", "batch", str(manifest), "--out", str(tmp_path / "c"), *options]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "S02" in err[0], err
    assert (tmp_path / "c" / "runs" / "S01" / "summary.json").exists()
    assert not (tmp_path / "c" / "runs" / "S02").exists()
    log = (tmp_path / "c" / "batch.json").read_text()
    assert "S02.png is 40x40 px, the frames are 96x96 px" in log

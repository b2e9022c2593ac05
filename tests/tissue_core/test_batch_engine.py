"""tissue_core.batch on a local Dask cluster with a stand-in command (tests/batch_jobs.py): a run
whose worker dies is made again, one whose workers keep dying is reported, an error is one line,
a defect does not end the batch, the others complete."""

import json
import os

# distributed's defaults must be in dask's config before any dask.config.set of a
# "distributed." key: set() inserts a missing section and deletes it whole on exit, taking
# with it the defaults that importing distributed added inside the block, for later tests
import dask
import distributed  # noqa: F401
import pytest

import tissue_core.resources as resources
from tissue_core.batch import Job, check_workers, run_batch
from tissue_core.errors import InputError


def _job(name: str, out, *flags: str) -> Job:
    run = out / "runs" / name
    return Job(name, "tests.batch_jobs", ("job", name, *flags, "--out", str(run)), str(run))


def test_a_local_cluster_restarts_a_killed_run_reports_errors_and_finishes_the_rest(tmp_path):
    jobs = [
        _job("good", tmp_path),
        _job("killed", tmp_path, "--crash-once", str(tmp_path / "killed-once")),
        _job("fail", tmp_path, "--fail"),
        _job("bug", tmp_path, "--bug"),
    ]
    outcomes = run_batch(jobs, tmp_path, workers=2)
    by_name = {o.name: o for o in outcomes}
    assert [o.name for o in outcomes] == ["good", "killed", "fail", "bug"]
    for name in ("good", "killed"):
        assert by_name[name].status == "done", by_name[name]
        assert (tmp_path / "runs" / name / "summary.json").is_file()
    assert by_name["killed"].worker_deaths >= 1  # its first worker died; another made it
    for name in ("good", "killed"):  # Dask's nannies set it; it slowed real runs by a third
        summary = json.loads((tmp_path / "runs" / name / "summary.json").read_text())
        assert summary["trim"] is None, "the workers started with MALLOC_TRIM_THRESHOLD_ set"
    for name in ("good", "fail", "bug"):  # one run at a time on a worker: none died with it
        assert by_name[name].worker_deaths == 0, by_name[name]
    assert by_name["fail"].reason == "fail: this input cannot be read"
    assert by_name["bug"].reason == "unexpected ZeroDivisionError: a defect"
    assert any("Traceback" in line for line in by_name["bug"].messages)
    record = json.loads((tmp_path / "batch.json").read_text())
    assert {r["name"]: r["status"] for r in record["runs"]} == {
        "bug": "failed", "fail": "failed", "good": "done", "killed": "done",
    }  # fmt: skip
    log = (tmp_path / "batch.log").read_text()
    assert "killed: done in" in log and "started again: its worker died" in log
    assert "ZeroDivisionError: a defect" in log  # the defect's traceback is kept
    assert not list((tmp_path / "runs").glob(".*"))
    # in one process the outcomes are the same
    again = run_batch(jobs[2:], tmp_path / "again", workers=1)
    assert [o.reason for o in again] == [by_name["fail"].reason, by_name["bug"].reason]


def test_a_run_whose_workers_keep_dying_is_reported(tmp_path):
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        (outcome,) = run_batch([_job("crash", tmp_path, "--crash")], tmp_path, workers=2)
    assert outcome.status == "failed" and "every worker that ran it died" in outcome.reason
    assert outcome.worker_deaths == 2  # the first run and its one retry
    assert not (tmp_path / "runs" / "crash").exists()


def test_while_no_run_ends_a_line_names_the_runs_in_progress(tmp_path, monkeypatch):
    import tissue_core.batch

    monkeypatch.setattr(tissue_core.batch, "HEARTBEAT_S", 0.3)
    lines = []
    jobs = [_job(name, tmp_path, "--sleep", "1.5") for name in ("a", "b", "c")]
    outcomes = run_batch(jobs, tmp_path, workers=2, say=lines.append)
    assert [o.status for o in outcomes] == ["done"] * 3
    progress = [line for line in lines if " running (" in line]
    assert "2 running (a, b), 1 waiting" in progress, lines  # one run per worker, c held back
    assert any(line.startswith("1 running (c), 0 waiting") for line in progress), lines


def test_one_batch_at_a_time_in_a_folder(tmp_path):
    import os
    import subprocess
    import sys

    from tissue_core.batch import LOCK_FILE
    from tissue_core.errors import InputError

    folder = tmp_path / "b"
    folder.mkdir()
    lock = folder / LOCK_FILE
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        lock.write_text(json.dumps({"host": os.uname().nodename, "pid": alive.pid}))
        try:
            run_batch([_job("a", folder)], folder, workers=1)
        except InputError as exc:
            assert f"another batch (process {alive.pid} on" in str(exc)
        else:
            raise AssertionError("a second batch ran in a folder in use")
        assert not (folder / "runs").exists()
    finally:
        alive.kill()
        alive.wait()
    # the lock of a batch that was killed is taken over
    (outcome,) = run_batch([_job("a", folder)], folder, workers=1)
    assert outcome.status == "done" and not lock.exists()


def test_options_given_to_a_batch_pass_on_as_typed_with_paths_made_absolute(tmp_path, monkeypatch):
    import argparse

    from tissue_core.batch import RunOptions

    monkeypatch.chdir(tmp_path)
    (tmp_path / "pts.csv").write_text("x,y\n1,2\n")
    parser = argparse.ArgumentParser()
    options = RunOptions(parser, "options")
    options.add_argument("--points")
    options.add_argument("--fps", type=float)
    args = parser.parse_args(["--points", "pts.csv", "--fps", "30"])
    argv = options.argv(args, {}, where="line 2")
    assert argv == ["--points", str(tmp_path / "pts.csv"), "--fps", "30"]
    assert options.argv(args, {"fps": "30"}, where="line 2") == argv  # a cell: the same run


def test_the_malloc_variable_dasks_nannies_set_is_found_and_unset_for_local_clusters(monkeypatch):
    from distributed import Client, LocalCluster

    from tissue_core.batch import _TRIM, _trimming, _without_malloc_trimming

    monkeypatch.delenv(_TRIM, raising=False)  # the nanny leaves it in this process's environment

    def found() -> bool:
        with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster:
            with Client(cluster) as client:
                return _trimming(client)

    assert found()  # Dask's default
    assert os.environ.get(_TRIM) is not None  # left behind by the nanny
    with _without_malloc_trimming():
        assert not found()
    assert os.environ.get(_TRIM) is not None  # given back


def test_a_batch_with_every_run_complete_says_nothing_runs_and_starts_no_cluster(tmp_path):
    jobs = [_job("a", tmp_path), _job("b", tmp_path)]
    assert [o.status for o in run_batch(jobs, tmp_path, workers=1)] == ["done", "done"]
    lines = []
    again = run_batch(jobs, tmp_path, workers=2, say=lines.append)
    assert [o.status for o in again] == ["skipped", "skipped"]
    assert lines[0].endswith("batch of 2 runs: 2 complete already, nothing to run"), lines
    assert not any("workers" in line for line in lines), lines  # no cluster was started


def test_manifest_columns_not_used_are_logged_and_a_misspelt_option_is_warned_of(tmp_path):
    import argparse

    import pytest

    from tissue_core.batch import RunOptions, manifest_jobs

    parser = argparse.ArgumentParser()
    options = RunOptions(parser, "options")
    options.add_argument("--grid")
    args = parser.parse_args([])
    (tmp_path / "a.txt").write_text("a")
    manifest = tmp_path / "m.csv"
    manifest.write_text("video,gird,notes\na.txt,9x9,left bladder\n")
    with pytest.warns(UserWarning, match="'gird' is not used: .*did you mean 'grid'"):
        jobs, _, unused = manifest_jobs(
            manifest, tmp_path / "b", options, args, module="tests.batch_jobs", command="job",
            sources=[("video", None)],
        )  # fmt: skip
    assert unused == ["gird", "notes"]  # 'notes' is like no option: no warning for it
    assert "9x9" not in jobs[0].argv
    note = f"manifest columns not used: {', '.join(unused)}"
    lines = []
    run_batch([_job("a", tmp_path)], tmp_path / "b", workers=1, say=lines.append, notes=[note])
    assert note in lines and note in (tmp_path / "b" / "batch.log").read_text()


def test_then_runs_one_more_job_where_the_runs_ran_with_their_outcomes(tmp_path, monkeypatch):
    """``then`` (strain2d batch's study) sees every outcome in order and makes its job on a
    worker of the cluster before it closes, saying so while it runs; in one process, and
    with nothing to run, here."""
    import tissue_core.batch

    monkeypatch.setattr(tissue_core.batch, "HEARTBEAT_S", 0.3)
    jobs = [_job("a", tmp_path), _job("fail", tmp_path, "--fail"), _job("b", tmp_path)]
    seen, lines = [], []

    def then(outcomes, run):
        seen.append([(o.name, o.status) for o in outcomes])
        seen.append(run(_job(f"after{len(seen)}", tmp_path, "--sleep", "1")))

    run_batch(jobs, tmp_path, workers=2, then=then, say=lines.append)
    assert seen[0] == [("a", "done"), ("fail", "failed"), ("b", "done")]
    on_cluster = seen[1]
    assert on_cluster.status == "done" and (tmp_path / "runs" / "after1").is_dir()
    assert on_cluster.worker.rsplit(":", 1)[1] != str(os.getpid())  # a worker made it
    assert "1 running (after1), 0 waiting" in lines, lines
    assert " after1: done in " in (tmp_path / "batch.log").read_text()  # the log says so
    assert not list((tmp_path / "runs").glob(".*"))

    seen.clear()  # all but the failing run complete: it alone runs, in this process
    run_batch(jobs, tmp_path, workers=1, then=then)
    assert seen[0] == [("a", "skipped"), ("fail", "failed"), ("b", "skipped")]
    assert seen[1].status == "done" and seen[1].worker.rsplit(":", 1)[1] == str(os.getpid())

    seen.clear()  # nothing to run at all
    run_batch(jobs[::2], tmp_path, workers=2, then=then)
    assert seen[0] == [("a", "skipped"), ("b", "skipped")]
    assert seen[1].status == "done" and seen[1].worker.rsplit(":", 1)[1] == str(os.getpid())


def test_ctrl_c_after_then_made_its_job_names_it_as_written_and_not_a_stale_one(tmp_path):
    """A Ctrl-C that ends the batch once ``then``'s job is made (its worker finished it as the
    cluster closed) counts it among the results written; one left by an earlier batch not."""
    import pytest

    from tissue_core.outputs import written

    stale = _job("stale", tmp_path / "earlier")
    run_batch([stale], tmp_path / "earlier", workers=1)  # complete before the batch began
    old = os.stat(stale.out).st_mtime
    os.utime(stale.out, (old - 60, old - 60))

    def then(outcomes, run):
        run(_job("after", tmp_path / "batch"))
        run(stale)  # complete already: nothing made
        raise KeyboardInterrupt

    written.clear()
    with pytest.raises(KeyboardInterrupt):
        run_batch([_job("a", tmp_path / "batch")], tmp_path / "batch", workers=2, then=then)
    assert str(tmp_path / "batch" / "runs" / "after") in written
    assert stale.out not in written
    log = (tmp_path / "batch" / "batch.log").read_text()
    assert "after: its worker finished it as the batch stopped" in log
    assert "stale: its worker" not in log


def test_more_workers_than_the_memory_holds_are_refused_before_any_starts(monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: 2**30)
    assert check_workers(8, None, 20) == 8  # 800 MiB: they fit
    with pytest.raises(InputError, match=r"--workers 100000 \(worker processes\) needs 9.54 TiB "
                       r"of memory; 1 GiB is available: use fewer --workers"):  # fmt: skip
        check_workers(100000, None, 20)


def test_a_batch_file_is_written_again_only_while_it_holds_what_a_batch_wrote(tmp_path):
    from tissue_core.batch import update_batch_file
    from tissue_core.outputs import LEDGER, written_here

    path = tmp_path / "table.csv"
    assert update_batch_file(path, "name\nA\n", overwrite=False) == "written"
    assert written_here(path) and (tmp_path / LEDGER).is_file()
    assert update_batch_file(path, "name\nA\n", overwrite=False) == "unchanged"
    assert update_batch_file(path, "name\nA\nB\n", overwrite=False) == "written"  # the batch's
    path.write_text("name,note\nA,edited by hand\n")  # now the user's
    assert not written_here(path)
    for _ in range(2):
        assert update_batch_file(path, "name\nA\nB\nC\n", overwrite=False) == "kept"
        assert path.read_text() == "name,note\nA,edited by hand\n"
    assert update_batch_file(path, "name\nA\nB\nC\n", overwrite=True) == "written"
    assert path.read_text() == "name\nA\nB\nC\n" and written_here(path)
    mine = tmp_path / "mine.csv"  # never written by a batch
    mine.write_text("name\nX\n")
    assert update_batch_file(mine, "name\nA\n", overwrite=False) == "kept"
    assert mine.read_text() == "name\nX\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [LEDGER, "mine.csv", "table.csv"]


def test_a_manifest_cell_written_inert_is_read_as_it_was_given(tmp_path):
    from tissue_core.batch import manifest_rows

    path = tmp_path / "m.csv"
    path.write_text("video,specimen,group\na.avi,'=1+2, '@SUM(A1)\nb.avi,=raw,'plain\n")
    rows = manifest_rows(path, required=("video",))
    assert [(r["specimen"], r["group"]) for r in rows] == [("=1+2", "@SUM(A1)"), ("=raw", "'plain")]

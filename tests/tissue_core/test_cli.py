"""The command runner, progress lines and Ctrl-C inside compiled code."""

import io
import os
import re
import signal
import time
import warnings

import numpy as np
import pytest
from numba import njit

from tissue_core.cli import ArgumentParser, run_command
from tissue_core.errors import InputError
from tissue_core.interrupt import deferred_interrupt, is_interrupt
from tissue_core.progress import Progress, close_open_lines

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(handler, capsys, **kwargs) -> tuple[int, str]:
    parser = ArgumentParser(prog="tool")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("go").set_defaults(handler=handler)
    status = run_command("tool", parser, ["go"], **kwargs)
    return status, capsys.readouterr().err


def test_errors_are_one_line_and_exit_2(capsys):
    def fail(args):
        raise InputError("bad value\nin two lines")

    assert run(fail, capsys) == (2, "tool go: error: bad value in two lines\n")

    def disk_full(args):
        raise OSError(28, "No space left on device", "/data/out/tracks.csv")

    status, err = run(disk_full, capsys)
    assert status == 2 and err.count("\n") == 1 and "No space left" in err


def test_an_allocation_no_check_foresaw_is_one_line_and_exit_2(capsys):
    def allocate(args):
        np.empty((10**7, 10**7))  # 728 TiB: NumPy's ArrayMemoryError

    status, err = run(allocate, capsys)
    assert status == 2 and err.count("\n") == 1
    assert err.startswith("tool go: error: not enough memory: Unable to allocate 728")
    assert err.endswith("shape (10000000, 10000000) and data type float64\n")

    def bare(args):
        raise MemoryError

    assert run(bare, capsys) == (2, "tool go: error: not enough memory: an allocation failed\n")


def test_warnings_are_one_line_and_numerical_ones_stay_in_the_log(capsys):
    def warn(args):
        warnings.warn("the stack has no spacing", UserWarning, stacklevel=1)
        return 0

    assert run(warn, capsys) == (0, "tool go: warning: the stack has no spacing\n")


def _interrupted_in_compiled_code(args):
    """What numba does when SIGINT arrives during a call back into Python."""
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("<function _numba_unpickle> returned a result") from exc
    except SystemError as exc:
        raise SystemError("CPUDispatcher(<function icgn>) returned a result") from exc


def test_ctrl_c_in_compiled_code_is_an_interruption(capsys):
    status, err = run(_interrupted_in_compiled_code, capsys)
    assert status == 130
    assert err == "tool go: interrupted; no output written\n"

    def other_system_error(args):
        raise SystemError("a real bug")

    with pytest.raises(SystemError, match="a real bug"):
        run(other_system_error, capsys)
    assert not is_interrupt(SystemError("x"))


def test_ctrl_c_while_a_bar_is_open_starts_a_new_line(capsys, monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    screen = Terminal()
    say = Progress(stream=screen)

    def interrupted(args):
        task = say.task("tracking (dic)")
        task(3, 31)
        raise KeyboardInterrupt

    status, err = run(interrupted, capsys)
    assert status == 130 and err == "tool go: interrupted; no output written\n"
    assert "tracking (dic)" in screen.getvalue()  # the bar was drawn, then cleared
    assert screen.getvalue().endswith("\r") or "\x1b" in screen.getvalue()[-8:]


def test_ctrl_c_while_parsing_is_an_interruption(capsys, monkeypatch):
    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ArgumentParser, "parse_args", interrupted)
    status, err = run(lambda args: 0, capsys)
    assert (status, err) == (130, "tool: interrupted; no output written\n")


def test_argument_parser_errors_are_one_line(capsys):
    parser = ArgumentParser(prog="tool")
    parser.add_argument("--n", type=int)
    with pytest.raises(SystemExit) as info:
        parser.parse_args(["--n", "x"])
    assert info.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_progress_in_a_log_is_timestamped_lines():
    log = io.StringIO()
    say = Progress(stream=log, interval=0.0)
    say("reading the video")
    with say.task("tracking (dic)") as task:
        for k in range(1, 4):
            task(k, 3)
    say("results in out/")
    lines = log.getvalue().splitlines()
    assert all(re.match(r"\[ +\d+\.\d s\] ", line) for line in lines), lines
    assert lines[0].endswith("] reading the video")
    assert lines[1].endswith("] tracking (dic): 1/3 frames")
    assert re.search(r"\] tracking \(dic\): 3/3 frames in \d+\.\d s$", lines[-2])
    assert lines[-1].endswith("] results in out/")
    quiet = io.StringIO()
    q = Progress(stream=quiet, quiet=True, interval=0.0)
    q("x")
    with q.task("y") as task:
        task(1, 1)
    assert quiet.getvalue() == ""
    close_open_lines()


@njit(cache=False)
def _busy(n):  # pragma: no cover - compiled
    total = 0.0
    for i in range(n):
        total += np.sqrt(i)
    return total


def test_ctrl_c_is_deferred_to_the_end_of_a_compiled_call():
    _busy(10)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt():
            os.kill(os.getpid(), signal.SIGINT)  # arrives "inside" the block
            done.append(_busy(1000))
            done.append("after the kernel")
    assert done[1] == "after the kernel"  # the block ran to its end first
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with deferred_interrupt():  # no signal: nothing raised
        _busy(10)


def test_a_ctrl_c_python_swallowed_is_raised_at_the_next_step(capsys):
    """KeyboardInterrupt in a finalizer: Python prints 'Exception ignored' and runs on."""
    import gc
    import weakref

    class Thing:
        pass

    def interrupted(args):
        thing = Thing()
        weakref.finalize(thing, _raise_keyboard_interrupt)
        del thing
        gc.collect()  # the finalizer's KeyboardInterrupt is swallowed here
        say = Progress(quiet=True)
        with say.task("work") as task:
            task(1, 2)  # ... and raised here
        return 0

    status, err = run(interrupted, capsys)
    assert (status, err) == (130, "tool go: interrupted; no output written\n")


def _raise_keyboard_interrupt():
    raise KeyboardInterrupt


def test_ctrl_c_after_the_result_was_written_says_so(tmp_path, capsys):
    from tissue_core.outputs import atomic_dir

    def finished_then_interrupted(args):
        with atomic_dir(tmp_path / "run") as tmp:
            (tmp / "a.csv").write_text("x")
        raise KeyboardInterrupt

    status, err = run(finished_then_interrupted, capsys)
    assert status == 130
    assert err == f"tool go: interrupted after the results were written to {tmp_path / 'run'}\n"
    status, err = run(lambda args: 0, capsys)  # the next command starts afresh
    assert (status, err) == (0, "")


def test_ctrl_c_during_an_import_waits_until_the_module_is_whole(tmp_path, monkeypatch, capsys):
    """A native extension left half-initialised by Ctrl-C can crash the process later."""
    import sys
    import time

    (tmp_path / "slow_module_for_test.py").write_text(
        "import os, signal, time\n"
        "os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C in the middle of the import\n"
        "time.sleep(0.2)\n"
        "WHOLE = True\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    reached = []

    def handler(args):
        import slow_module_for_test

        reached.append(slow_module_for_test.WHOLE)
        time.sleep(5)  # the held Ctrl-C is delivered here, once the import is done
        reached.append("slept")
        return 0

    try:
        status, err = run(handler, capsys)
    finally:
        sys.modules.pop("slow_module_for_test", None)
    assert (status, err) == (130, "tool go: interrupted; no output written\n")
    assert reached == [True]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_finalizers_of_what_ctrl_c_left_half_built_stay_quiet(capsys):
    """Ctrl-C inside a constructor leaves an object whose __del__ fails: not a traceback."""

    class HalfBuilt:
        def __init__(self):
            raise KeyboardInterrupt  # Ctrl-C before the attribute is set

        def __del__(self):
            self.expr  # noqa: B018 - AttributeError, as pyparsing's Forward does

    def interrupted(args):
        HalfBuilt()

    assert run(interrupted, capsys) == (130, "tool go: interrupted; no output written\n")


def test_a_ctrl_c_held_in_a_failing_block_wins_and_is_not_left_behind():
    import time

    from tissue_core.interrupt import raise_if_interrupted

    with pytest.raises(KeyboardInterrupt) as info:
        with deferred_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler runs, and holds it
            raise ValueError("the block's own error")
    assert isinstance(info.value.__cause__, ValueError)
    with deferred_interrupt():  # a later, unrelated block: nothing pending
        pass
    raise_if_interrupted()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


# ---- SIGTERM and SIGHUP: the same path as Ctrl-C -----------------------------------------

TERMINATING = [
    pytest.param(signal.SIGTERM, 143, "SIGTERM", id="sigterm"),
    pytest.param(signal.SIGHUP, 129, "SIGHUP", id="sighup"),
]


@pytest.mark.parametrize(("signum", "status", "name"), TERMINATING)
def test_sigterm_and_sighup_end_a_command_as_ctrl_c_does(signum, status, name, tmp_path, capsys):
    from tissue_core.interrupt import Terminated
    from tissue_core.outputs import atomic_dir

    caught = []

    def terminated(args):
        try:
            with atomic_dir(tmp_path / "run") as tmp:
                (tmp / "a.csv").write_text("half")
                os.kill(os.getpid(), signum)  # kill PID, timeout, scancel; a closed terminal
                time.sleep(5)
        except KeyboardInterrupt as exc:  # every except KeyboardInterrupt sees it
            caught.append(exc)
            raise
        return 0

    assert run(terminated, capsys) == (status, f"tool go: terminated ({name}); no output written\n")
    assert isinstance(caught[0], Terminated) and caught[0].signum == signum
    assert is_interrupt(caught[0])
    assert list(tmp_path.iterdir()) == []  # no result, no scratch
    assert signal.getsignal(signum) is signal.SIG_DFL  # Python's own handling is back


def test_sigterm_after_the_result_was_written_says_so(tmp_path, capsys):
    from tissue_core.outputs import atomic_dir

    def finished_then_terminated(args):
        with atomic_dir(tmp_path / "run") as tmp:
            (tmp / "a.csv").write_text("x")
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
        return 0

    status, err = run(finished_then_terminated, capsys)
    assert status == 143
    assert err == (
        f"tool go: terminated (SIGTERM) after the results were written to {tmp_path / 'run'}\n"
    )


def test_sigterm_is_deferred_to_the_end_of_a_compiled_call(capsys):
    _busy(10)
    done = []

    def kernel(args):
        with deferred_interrupt():
            os.kill(os.getpid(), signal.SIGTERM)  # arrives "inside" the kernel
            done.append(_busy(1000))
            done.append("after the kernel")
        done.append("after the block")
        return 0

    assert run(kernel, capsys) == (143, "tool go: terminated (SIGTERM); no output written\n")
    assert done[1:] == ["after the kernel"]  # the block ran to its end, and no further


def test_a_sigterm_library_code_swallowed_is_raised_at_the_next_step(capsys):
    reached = []

    def swallowed(args):
        try:  # Python code that catches everything and goes on
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
        except BaseException:
            pass
        reached.append("went on")
        with Progress(quiet=True).task("work") as task:
            task(1, 2)  # ... raised again here
        reached.append("finished")
        return 0

    assert run(swallowed, capsys) == (143, "tool go: terminated (SIGTERM); no output written\n")
    assert reached == ["went on"]


def test_sigterm_during_an_import_waits_and_is_sent_again_as_sigterm(tmp_path, monkeypatch, capsys):
    import sys

    (tmp_path / "slow_module_for_sigterm.py").write_text(
        "import os, signal, time\n"
        "os.kill(os.getpid(), signal.SIGTERM)  # SIGTERM in the middle of the import\n"
        "time.sleep(0.2)\n"
        "WHOLE = True\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    reached = []

    def handler(args):
        import slow_module_for_sigterm

        reached.append(slow_module_for_sigterm.WHOLE)
        time.sleep(5)  # the held SIGTERM is delivered here, once the import is done
        reached.append("slept")
        return 0

    try:
        status, err = run(handler, capsys)
    finally:
        sys.modules.pop("slow_module_for_sigterm", None)
    assert (status, err) == (143, "tool go: terminated (SIGTERM); no output written\n")
    assert reached == [True]


def test_sighup_with_the_terminal_gone_ends_without_a_traceback(monkeypatch):
    """After SIGHUP stderr may be a closed terminal: writing to it fails (EIO)."""

    class ClosedTerminal(io.StringIO):
        def write(self, text):
            raise OSError(5, "Input/output error")

        def isatty(self):
            return True

    monkeypatch.setattr("sys.stderr", ClosedTerminal())

    def hung_up(args):
        os.kill(os.getpid(), signal.SIGHUP)
        time.sleep(5)
        return 0

    parser = ArgumentParser(prog="tool")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("go").set_defaults(handler=hung_up)
    assert run_command("tool", parser, ["go"]) == 129


def test_an_ignored_sighup_stays_ignored(capsys, request):
    """``nohup`` ignores SIGHUP so that the command outlives its terminal."""
    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    request.addfinalizer(lambda: signal.signal(signal.SIGHUP, previous))

    def hung_up(args):
        os.kill(os.getpid(), signal.SIGHUP)
        time.sleep(0.1)
        return 0

    assert run(hung_up, capsys) == (0, "")
    assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN


def test_libraries_log_lines_reach_the_terminal_only_with_verbose(tmp_path):
    """tifffile logs ``ERROR: ...`` on a damaged file and carries on: without -v the toolkit's
    one error line must stay the only line (in a process of its own: pytest keeps the log)."""
    import subprocess
    import sys

    script = tmp_path / "tool.py"
    script.write_text(
        "import logging, sys\n"
        "from tissue_core.cli import CommandLine, run_command\n"
        "from tissue_core.errors import InputError\n"
        "def go(args):\n"
        "    logging.getLogger('tifffile').error('<tifffile.TiffPages @8> invalid page offset')\n"
        "    logging.getLogger('tissue_core.outputs').warning('the toolkit says this')\n"
        "    raise InputError('the one line')\n"
        "cli = CommandLine('tool', 'A test.')\n"
        "cli.command('go', go)\n"
        "sys.exit(run_command('tool', cli, sys.argv[1:]))\n"
    )
    runs = {
        flag: subprocess.run(
            [sys.executable, str(script), "go", *flags], capture_output=True, text=True,
            cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)},
        )
        for flag, flags in (("quiet", []), ("verbose", ["-v"]))
    }  # fmt: skip
    assert runs["quiet"].returncode == 2
    assert runs["quiet"].stderr.splitlines() == [
        "WARNING: the toolkit says this",
        "tool go: error: the one line",
    ]
    assert "ERROR: <tifffile.TiffPages @8> invalid page offset" in runs["verbose"].stderr

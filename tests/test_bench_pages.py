"""bench/page.py: a bench script's output becomes a documentation page, written only by
the runner, never over a page someone wrote by hand, never from a failed run."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _page_module():
    spec = importlib.util.spec_from_file_location("bench_page", ROOT / "bench" / "page.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


page = _page_module()


def test_a_page_holds_the_description_the_command_the_machine_and_the_output():
    output = "a first line\n\n| case | time (s) |\n|---|---|\n| sheet | 1.2 |\nspeed-up: 3x\n"
    text = page.render(
        ROOT / "bench" / "bench_kinematics.py", ["--grid", "5"], output, "WHEN", "MACHINE"
    )
    lines = text.splitlines()
    assert page.as_written(text)
    assert lines[0].startswith("<!-- written by bench/page.py (sha256 ")
    assert lines[1] == "# Speed of the vectorized strain computation against a per-triangle loop"
    assert "`python bench/bench_kinematics.py --grid 5`" in text
    assert "on WHEN" in text and "- Machine: MACHINE" in text
    # the table passes through as a table; the other lines are kept as printed
    at = lines.index("| case | time (s) |")
    assert lines[at : at + 3] == ["| case | time (s) |", "|---|---|", "| sheet | 1.2 |"]
    assert lines[at - 1] == "" and lines[at + 3] == ""
    assert "```text\na first line\n```" in text
    assert "```text\nspeed-up: 3x\n```" in text


def test_the_machine_line_names_cores_python_and_commit():
    line = page.machine()
    assert re.search(r"\d+ cores", line)
    assert "Python 3." in line and "tissue-strain" in line and " at " in line


def test_a_run_writes_the_page_and_a_failed_or_foreign_page_is_left_alone(tmp_path, capsys):
    argv = ["bench_kinematics.py", "--grid", "4", "--frames", "2", "--pages", str(tmp_path)]
    assert page.main(argv) == 0
    written = tmp_path / "bench_kinematics.md"
    text = written.read_text(encoding="utf-8")
    assert page.as_written(text)
    assert "16 points" in text and "speed-up:" in text
    assert "python bench/bench_kinematics.py --grid 4 --frames 2" in text
    assert not list(tmp_path.glob(".*partial"))

    # a failing run (an option the script refuses) leaves the page as it was
    assert page.main(["bench_kinematics.py", "--grid", "x", "--pages", str(tmp_path)]) == 2
    assert written.read_text(encoding="utf-8") == text
    assert "page not written" in capsys.readouterr().err

    # a page the runner wrote and someone then changed is not replaced without --overwrite
    edited = text.replace("## Output", "## Output\n\nmy remark", 1)
    written.write_text(edited, encoding="utf-8")
    assert page.main(argv) == 2
    assert written.read_text(encoding="utf-8") == edited
    assert "changed since" in capsys.readouterr().err

    # nor a page someone wrote by hand
    written.write_text("# my notes\n", encoding="utf-8")
    assert page.main(argv) == 2
    assert written.read_text(encoding="utf-8") == "# my notes\n"
    assert "--overwrite" in capsys.readouterr().err
    assert page.main([*argv, "--overwrite"]) == 0
    assert page.as_written(written.read_text(encoding="utf-8"))


def test_sigterm_ends_the_script_and_writes_no_page(tmp_path):
    import signal
    import subprocess
    import time

    # a run of about 30 s: the loop baseline over 400 frames of a 60 x 60 grid
    args = ["--grid", "60", "--frames", "400", "--pages", str(tmp_path)]
    pattern = "bench_kinematics.py --grid 60 --frames 400 --pages " + str(tmp_path)

    def script_running() -> bool:
        found = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True)
        return bool(found.stdout.strip())

    runner = subprocess.Popen(
        [sys.executable, str(ROOT / "bench" / "page.py"), "bench_kinematics.py", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 30
    while not script_running():  # the script has started under the runner
        assert time.monotonic() < deadline and runner.poll() is None
        time.sleep(0.05)
    time.sleep(0.5)
    runner.send_signal(signal.SIGTERM)
    _, err = runner.communicate(timeout=60)
    assert runner.returncode == 128 + signal.SIGTERM, err
    assert "page not written" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []
    deadline = time.monotonic() + 10
    while script_running():  # the script ends with the runner
        assert time.monotonic() < deadline, "the script went on after the runner ended"
        time.sleep(0.05)


@pytest.mark.parametrize("name", ["no_such_bench.py", "page.py", "../tests/conftest.py"])
def test_only_a_bench_script_can_be_run(name, tmp_path, capsys):
    assert page.main([name, "--pages", str(tmp_path)]) == 2
    assert "no bench script" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_every_bench_page_was_written_by_the_runner_from_a_script_that_exists():
    pages = sorted((ROOT / "docs" / "bench").glob("*.md"))
    assert pages, "docs/bench/ has no page"
    for path in pages:
        text = path.read_text(encoding="utf-8")
        assert page.as_written(text), f"{path.name}: not written by bench/page.py, or edited"
        assert (ROOT / "bench" / f"{path.stem}.py").is_file(), f"{path.name}: no such script"
        assert "## Output" in text


def test_the_benchmarks_page_links_every_bench_page():
    text = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    for path in sorted((ROOT / "docs" / "bench").glob("*.md")):
        assert f"bench/{path.name}" in text, f"docs/benchmarks.md does not link {path.name}"


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__]))

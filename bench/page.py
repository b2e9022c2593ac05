"""Run a bench script and write what it prints as a page of the documentation.

    python bench/page.py bench_analyze.py [ARGS...]

runs ``python bench/bench_analyze.py ARGS`` here, shows its output as it
comes, and, if it succeeds, writes ``docs/bench/bench_analyze.md``: the
script's own description (its docstring), the command, when and on what
machine it ran (processor, cores, memory, Python, the toolkit's version and
commit), and its output. Markdown tables pass through as tables; the lines
between them are shown as they were printed. A failing run leaves the page as
it was; Ctrl-C, SIGTERM or SIGHUP end the script and write nothing. Only this
runner replaces a page: one without its mark, or changed since it was
written (the mark holds the SHA-256 of the rest), is refused without
``--overwrite``.

``make bench-pages`` writes the pages of the scripts quick enough to rerun
often; the others are written by hand with this runner (see
docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import ast
import datetime
import hashlib
import os
import platform
import re
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's packages
from tissue_core.interrupt import exit_status, handling_interrupts  # noqa: E402

BENCH = ROOT / "bench"
PAGES = ROOT / "docs" / "bench"
#: the first line of every page this runner writes, with the SHA-256 of the rest of the page
MARK = "<!-- written by bench/page.py (sha256 {}): rerun the command below to update this page -->"
_MARK = re.compile(re.escape(MARK).replace(re.escape("{}"), "([0-9a-f]{64})"))


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def as_written(text: str) -> bool:
    """Whether ``text`` is a page as this runner wrote it (its mark, and nothing changed since)."""
    first, _, rest = text.partition("\n")
    found = _MARK.fullmatch(first)
    return bool(found) and found.group(1) == _digest(rest)


def _memory_gib() -> float | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        return None


def _processor() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _commit() -> str:
    try:
        out = subprocess.run(
            ["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def machine() -> str:
    """One line: processor, cores, memory, Python, version and commit."""
    from tissue_core import __version__

    memory = _memory_gib()
    return (
        f"{_processor()}, {os.cpu_count()} cores"
        + (f", {memory:.0f} GiB" if memory else "")
        + f"; Python {platform.python_version()}, {platform.system()}; "
        f"tissue-strain {__version__} at {_commit()}"
    )


def description(script: Path) -> tuple[str, str]:
    """The script's title (its docstring's first line) and the rest of its docstring."""
    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))) or script.stem
    title, _, rest = doc.partition("\n")
    return title.strip().rstrip("."), rest.strip()


def render(script: Path, argv: list[str], output: str, when: str, on: str) -> str:
    """The page's Markdown."""
    title, about = description(script)
    command = " ".join(["python", f"bench/{script.name}", *argv])
    body, text = [], []  # the page's lines; the run of lines outside tables so far

    def flush():
        while text and not text[-1].strip():
            text.pop()
        if text:
            body.extend(["```text", *text, "```", ""])
        text.clear()

    for line in output.rstrip().splitlines():
        if line.lstrip().startswith("|"):  # a table's row: Markdown as it is
            flush()
            body.append(line.strip())
        else:
            if body and body[-1].startswith("|"):
                body.append("")
            if line.strip() or text:
                text.append(line.rstrip())
    flush()
    about_md = f"```text\n{about}\n```\n\n" if about else ""
    page = (
        f"# {title}\n\n"
        f"Written by `python bench/page.py {script.name}"
        + (" " + " ".join(argv) if argv else "")
        + f"` on {when}.\n\n"
        f"- Command: `{command}`\n- Machine: {on}\n\n"
        f"## What it measures\n\n{about_md}"
        "## Output\n\n" + "\n".join(body).strip() + "\n"
    )
    return MARK.format(_digest(page)) + "\n" + page


def main(args: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("script", help="a bench script, e.g. bench_analyze.py")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace a page that this runner did not write")  # fmt: skip
    parser.add_argument("--pages", type=Path, default=PAGES, help="folder of the pages")
    known, rest = parser.parse_known_args(args)
    script = BENCH / Path(known.script).name
    if not script.is_file() or script.suffix != ".py" or script.name == Path(__file__).name:
        print(f"error: no bench script {known.script!r} in bench/", file=sys.stderr)
        return 2
    page = known.pages / f"{script.stem}.md"
    if page.exists() and not known.overwrite:
        if not as_written(page.read_text(encoding="utf-8", errors="replace")):
            print(f"error: {page} was not written by this runner, or was changed since "
                  "(--overwrite replaces it)", file=sys.stderr)  # fmt: skip
            return 2
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = []
    with handling_interrupts():  # Ctrl-C, SIGTERM and SIGHUP end the script too
        try:
            with subprocess.Popen(
                [sys.executable, str(script), *rest],
                cwd=ROOT,
                stdout=subprocess.PIPE,
                encoding="utf-8",
                errors="replace",  # a byte that is not UTF-8 shows as such, not as a traceback
            ) as child:
                try:
                    for line in child.stdout:
                        sys.stdout.write(line)
                        sys.stdout.flush()
                        lines.append(line)
                except KeyboardInterrupt:
                    child.terminate()
                    raise
        except KeyboardInterrupt as stop:
            print(f"interrupted: {script.name}; page not written", file=sys.stderr)
            return exit_status(getattr(stop, "signum", signal.SIGINT))
    if child.returncode != 0:
        print(f"error: {script.name} failed (status {child.returncode}); page not written",
              file=sys.stderr)  # fmt: skip
        return 2
    text = render(script, rest, "".join(lines), when, machine())
    try:
        page.parent.mkdir(parents=True, exist_ok=True)
        tmp = page.with_name(f".{page.name}.partial")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, page)
    except OSError as error:
        print(f"error: cannot write {page}: {error.strerror or error}", file=sys.stderr)
        return 2
    print(f"wrote {page.relative_to(ROOT) if page.is_relative_to(ROOT) else page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Run a bench script and write what it prints as a page of the documentation.

    python bench/page.py bench_analyze.py [ARGS...]

runs ``python bench/bench_analyze.py ARGS`` here, shows its output as it
comes, and, if it succeeds, writes ``docs/bench/bench_analyze.md``: the
script's own description (its docstring), the command, when and on what
machine it ran (processor, cores, memory, Python, the toolkit's version and
commit), and its output. Markdown tables pass through as tables; the lines
between them are shown as they were printed. The page is replaced only by another run of its script:
one whose first line is not this runner's mark is refused without
``--overwrite``. A failing run leaves the page as it was.

``make bench-pages`` writes the pages of the scripts quick enough to rerun
often; the others are written by hand with this runner (see
docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import ast
import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
PAGES = ROOT / "docs" / "bench"
#: the first line of every page this runner writes
MARK = "<!-- written by bench/page.py: rerun the command below to update this page -->"


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
    return (
        f"{MARK}\n# {title}\n\n"
        f"Written by `python bench/page.py {script.name}"
        + (" " + " ".join(argv) if argv else "")
        + f"` on {when}.\n\n"
        f"- Command: `{command}`\n- Machine: {on}\n\n"
        f"## What it measures\n\n{about_md}"
        "## Output\n\n" + "\n".join(body).strip() + "\n"
    )


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
        first = page.read_text(encoding="utf-8", errors="replace").partition("\n")[0]
        if first != MARK:
            print(f"error: {page} was not written by this runner (--overwrite replaces it)",
                  file=sys.stderr)  # fmt: skip
            return 2
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = []
    try:
        with subprocess.Popen(
            [sys.executable, str(script), *rest],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            encoding="utf-8",
            errors="replace",  # a byte that is not UTF-8 shows as such, not as a traceback
        ) as child:
            for line in child.stdout:
                sys.stdout.write(line)
                sys.stdout.flush()
                lines.append(line)
    except KeyboardInterrupt:  # the script got the same Ctrl-C
        print(f"interrupted: {script.name}; page not written", file=sys.stderr)
        return 130
    if child.returncode != 0:
        print(f"error: {script.name} failed (status {child.returncode}); page not written",
              file=sys.stderr)  # fmt: skip
        return 2
    text = render(script, rest, "".join(lines), when, machine())
    page.parent.mkdir(parents=True, exist_ok=True)
    tmp = page.with_name(f".{page.name}.partial")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, page)
    print(f"wrote {page.relative_to(ROOT) if page.is_relative_to(ROOT) else page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

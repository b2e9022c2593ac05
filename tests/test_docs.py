"""The documentation: the site builds with no warning, the API reference covers every public
module, the README is a front door that links to every guide, and every command the guides
show is one the command lines accept."""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: the command-line module of each package a guide may call with ``python -m``
CLIS = {
    "strain2d": "strain2d.cli",
    "surface_strain": "surface_strain.cli",
    "stereo": "stereo.cli",
    "mpm3d": "mpm3d.cli",
    "multimodal": "multimodal.cli",
    "sample_data_synth": "sample_data_synth.cli",
}


def _gen_api():
    spec = importlib.util.spec_from_file_location("gen_api", DOCS / "gen_api.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _nav_pages(entry) -> list[str]:
    if isinstance(entry, str):
        return [entry]
    if isinstance(entry, list):
        return [p for item in entry for p in _nav_pages(item)]
    return [p for value in entry.values() for p in _nav_pages(value)]


def _config() -> dict:
    # mkdocs.yml holds no tags that need mkdocs' own loader
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))


def test_the_site_builds_offline_with_no_warning(tmp_path):
    """``mkdocs build --strict``: a broken link, a missing page or a docstring that
    mkdocstrings cannot parse fails the build."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    site = tmp_path / "site"
    for page in ("index.html", "strain2d/index.html", "formats/index.html", "api/mpm3d/index.html"):
        assert (site / page).is_file(), page
    api = (site / "api" / "mpm3d" / "index.html").read_text(encoding="utf-8")
    assert 'id="mpm3d.mosaic.open_mosaic"' in api  # rendered from its docstring
    assert 'id="mpm3d.analyze.analyze_stack"' in api
    # every public name of every public module is on an API page: where it is defined,
    # or where it is exported (a constant by its name in any module)
    ids = set()
    for page in (site / "api").glob("*/index.html"):
        ids |= set(re.findall(r'id="([\w.]+)"', page.read_text(encoding="utf-8")))
    gen = _gen_api()
    missing = []
    for package, _ in gen.PACKAGES:
        for name in gen.public_modules(package):
            module = importlib.import_module(name)
            for public in getattr(module, "__all__", []):
                if public.startswith("__"):
                    continue
                where = {
                    f"{name}.{public}",
                    f"{getattr(getattr(module, public), '__module__', '')}.{public}",
                }
                if not where & ids and not any(i.endswith(f".{public}") for i in ids):
                    missing.append(f"{name}.{public}")
    assert missing == []


def test_every_page_is_in_the_navigation():
    pages = set(_nav_pages(_config()["nav"]))
    on_disk = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    assert on_disk == pages


@pytest.mark.parametrize("package", [p for p, _ in _gen_api().PACKAGES])
def test_the_api_reference_covers_every_public_module(package):
    """The API pages are what ``docs/gen_api.py`` writes now: every public module of the
    package (run it after adding one)."""
    gen = _gen_api()
    page = (DOCS / "api" / f"{package}.md").read_text(encoding="utf-8")
    assert page == gen.page(package, dict(gen.PACKAGES)[package])
    modules = gen.public_modules(package)
    assert package in modules and len(modules) >= 3
    for name in modules:
        assert f"::: {name}\n" in page


def test_every_package_has_an_api_page():
    gen = _gen_api()
    packages = {p for p, _ in gen.PACKAGES}
    assert packages == {p.parent.name for p in ROOT.glob("*/__init__.py")} - {"tests"}


def test_the_readme_is_a_front_door():
    """Under 15 KB; it links to every user guide and reference page, and every file it
    links to or shows exists."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.encode("utf-8")) < 15_000
    targets = re.findall(r"\]\(([^)\s#]+)(?:#[^)]*)?\)", readme)
    local = [t for t in targets if not t.startswith(("http://", "https://"))]
    for target in local:
        assert (ROOT / target).exists(), target
    nav = _config()["nav"]
    guides = [p for item in nav for key, value in item.items() if key in ("User guides",)
              for p in _nav_pages(value)]  # fmt: skip
    assert len(guides) >= 8
    for page in [*guides, "formats.md", "reliability.md", "benchmarks.md", "index.md"]:
        assert f"docs/{page}" in local, page
    for command in ("make demo", "make test"):
        assert command in readme


def _blocks(text: str):
    """Each fenced block's ``(needs, steps)``: ``needs`` is the reason of a ``<!-- needs:
    ... -->`` line just before it (its commands need data or means a test does not
    have), or None; ``steps`` are its ``("run", command)``, ``("cd", folder)`` and
    ``("mkdir", folder)`` lines in order (continuations joined, comments and a shell
    prompt taken off)."""
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        if not lines[k].startswith("```"):
            k += 1
            continue
        before = lines[k - 1].strip() if k else ""
        m = re.fullmatch(r"<!-- needs: (.+) -->", before)
        needs = m.group(1) if m else None
        body = []
        k += 1
        while k < len(lines) and not lines[k].startswith("```"):
            body.append(lines[k])
            k += 1
        k += 1
        steps, so_far = [], ""
        for line in body:
            line = line.rstrip()
            if so_far:
                so_far += " " + line.strip()
            elif re.match(r"^\$?\s*python -m \w+", line):
                so_far = re.sub(r"^\$\s*", "", line.strip())
            elif re.match(r"^\$?\s*(cd|mkdir -p) \S+(\s+#.*)?$", line.strip()):
                words = line.strip().lstrip("$ ").split(" #")[0].split()
                steps.append(("cd", words[1]) if words[0] == "cd" else ("mkdir", words[-1]))
                continue
            else:
                continue
            if so_far.endswith("\\"):
                so_far = so_far[:-1]
                continue
            steps.append(("run", so_far.split(" #")[0].strip()))
            so_far = ""
        if any(kind == "run" for kind, _ in steps):
            yield needs, steps


def _commands(text: str):
    """The ``python -m PACKAGE ...`` lines of a page's code blocks (continuations joined,
    comments and a shell prompt taken off)."""
    inside, line_so_far = False, ""
    for line in text.splitlines():
        if line.startswith("```"):
            inside = not inside
            continue
        if not inside:
            continue
        line = line.rstrip()
        if line_so_far:
            line_so_far += " " + line.strip()
        elif re.match(r"^\$?\s*python -m \w+", line):
            line_so_far = re.sub(r"^\$\s*", "", line.strip())
        else:
            continue
        if line_so_far.endswith("\\"):
            line_so_far = line_so_far[:-1]
            continue
        yield line_so_far.split(" #")[0].strip()
        line_so_far = ""


def _guide_commands():
    pages = [*sorted(DOCS.glob("*.md")), ROOT / "README.md"]
    return [
        pytest.param(page.name, command, id=f"{page.name}:{k}")
        for page in pages
        for k, command in enumerate(_commands(page.read_text(encoding="utf-8")))
    ]


@pytest.mark.parametrize(("page", "command"), _guide_commands())
def test_every_command_shown_is_accepted(page, command):
    """Each command in the guides and the README is parsed by its package's own command
    line: the command, every option and every value's form exist (the files it names
    are the guide's example; ``make demo`` runs the demo's commands)."""
    argv = shlex.split(command)
    assert argv[:2] == ["python", "-m"], command
    if argv[2] == "tissue_napari":  # opens napari: its arguments are paths to open
        assert importlib.util.find_spec("tissue_napari.__main__") is not None
        assert all(not a.startswith("-") for a in argv[3:]), command
        return
    assert argv[2] in CLIS, f"{page}: no command line {argv[2]!r}"
    cli = importlib.import_module(CLIS[argv[2]])._build_parser()
    try:
        cli.parse_args(argv[3:])
    except SystemExit as exc:
        assert exc.code in (0, None), f"{page}: {command}"


def test_the_guides_show_commands():
    assert len(_guide_commands()) >= 50


def _pages_with_commands() -> list[Path]:
    return [p for p in [*sorted(DOCS.glob("*.md")), ROOT / "README.md"]
            if list(_blocks(p.read_text(encoding="utf-8")))]  # fmt: skip


def test_every_block_of_commands_runs_or_says_what_it_needs():
    """A block of commands is run by ``make docs-check`` unless a ``<!-- needs: ... -->``
    line says what it needs (the user's data, the demo's, a cluster, a display)."""
    reasons = []
    for page in _pages_with_commands():
        for needs, _ in _blocks(page.read_text(encoding="utf-8")):
            assert needs is None or len(needs.split()) >= 2, f"{page}: needs {needs!r}"
            reasons.append(needs)
    assert reasons.count(None) >= 8  # the worked examples run


@pytest.mark.guide_commands
@pytest.mark.parametrize("page", _pages_with_commands(), ids=lambda p: p.name)
def test_the_guides_commands_run(page, tmp_path):
    """Every command of the page's blocks that need nothing, run in order as a user would
    (in an empty folder; ``cd`` lines followed): each ends with status 0.  Slow (minutes):
    ``make docs-check`` runs it, the suite does not."""
    cwd = tmp_path
    ran = 0
    for needs, steps in _blocks(page.read_text(encoding="utf-8")):
        if needs is not None:
            continue
        for kind, command in steps:
            if kind == "cd":
                cwd = cwd / command
                continue
            if kind == "mkdir":
                (cwd / command).mkdir(parents=True, exist_ok=True)
                continue
            argv = shlex.split(command)
            done = subprocess.run([sys.executable, *argv[1:]], cwd=cwd, capture_output=True,
                                  text=True, timeout=900)  # fmt: skip
            assert done.returncode == 0, f"{page.name}: {command}\n{done.stderr[-2000:]}"
            ran += 1
    needs = [n for n, _ in _blocks(page.read_text(encoding="utf-8")) if n is not None]
    assert ran or needs, page

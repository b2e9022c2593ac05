"""The import graph of the code matches docs/ARCHITECTURE.md.

Each package imports only the packages its row of the table names, and only
through their public names (``from strain2d import track``, a name in
``strain2d.__all__``); tissue_core's modules are its public API; modules whose
names start with ``_`` are private everywhere.
"""

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = (
    "tissue_core",
    "sample_data_synth",
    "surface_strain",
    "mpm3d",
    "strain2d",
    "stereo",
    "multimodal",
    "tissue_napari",
)


def allowed_imports() -> dict[str, set[str]]:
    """The 'may import' table of docs/ARCHITECTURE.md."""
    text = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    table = {}
    for package, allowed in re.findall(r"^\| (\w+) \| ([\w, -]+) \|$", text, flags=re.M):
        if package in PACKAGES:
            table[package] = {a.strip() for a in allowed.split(",") if a.strip() != "-"}
    return table


def imports_of(package: str):
    """(file, line, module, names) of every import of another toolkit package."""
    for path in sorted((ROOT / package).rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    yield path, node.lineno, alias.name, []
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                yield path, node.lineno, node.module, [a.name for a in node.names]


def violations(package: str, table: dict[str, set[str]]) -> list[str]:
    found = []
    for path, line, module, names in imports_of(package):
        top = module.split(".")[0]
        if top not in PACKAGES or top == package:
            continue
        where = f"{path.relative_to(ROOT)}:{line}"
        if top not in table[package]:
            found.append(f"{where}: {package} may not import {top}")
        elif top == "tissue_core":
            if any(part.startswith("_") for part in module.split(".")[1:]):
                found.append(f"{where}: {module} is private")
        elif module != top:
            found.append(f"{where}: {module} is {top}'s internals; import from {top}")
        else:
            public = set(importlib.import_module(top).__all__)
            found += [f"{where}: {top}.{n} is not public" for n in names if n not in public]
    return found


def test_the_table_names_every_package_in_layers():
    table = allowed_imports()
    assert set(table) == set(PACKAGES)
    # ordered layers, hence no cycles: a package imports only packages of earlier rows
    order = list(table)
    for package, allowed in table.items():
        assert all(order.index(a) < order.index(package) for a in allowed), package


@pytest.mark.parametrize("package", PACKAGES)
def test_imports_follow_the_architecture(package):
    assert violations(package, allowed_imports()) == []


def test_the_check_finds_what_it_looks_for(tmp_path, monkeypatch):
    """A wrong arrow, another package's internals and a private name are each caught."""
    fake = tmp_path / "mpm3d"
    fake.mkdir()
    (fake / "bad.py").write_text(
        "from strain2d import track\n"
        "from tissue_core._private import x\n"
        "import surface_strain.field\n"
    )
    monkeypatch.setattr(
        "tests.test_architecture.ROOT", tmp_path, raising=True
    )  # imports_of reads ROOT / package
    table = {p: set() for p in PACKAGES} | {"mpm3d": {"tissue_core", "surface_strain"}}
    found = violations("mpm3d", table)
    assert len(found) == 3
    assert "may not import strain2d" in found[0]
    assert "is private" in found[1]
    assert "internals" in found[2]
    table["stereo"] = {"strain2d"}
    (tmp_path / "stereo").mkdir()
    (tmp_path / "stereo" / "x.py").write_text("from strain2d import not_a_public_name\n")
    assert violations("stereo", table) == [
        "stereo/x.py:1: strain2d.not_a_public_name is not public"
    ]

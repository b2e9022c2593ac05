"""Write the API reference pages (``docs/api/PACKAGE.md``): every public module of every
package, each rendered by mkdocstrings from its numpydoc docstrings.

    python docs/gen_api.py        # rewrite the pages (``make docs`` runs it first)

A module is public when no part of its dotted name starts with an underscore; within a
module, mkdocstrings shows its public names (``__all__`` where the module has one).
``tests/test_docs.py`` checks that the pages list every public module.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the packages, from the ground floor up (docs/ARCHITECTURE.md)
PACKAGES = (
    ("tissue_core", "the ground floor: errors, outputs, tables, progress, batches"),
    ("strain2d", "video to strain: trackers, mesh, strain, figures, studies"),
    ("surface_strain", "membrane kinematics on triangulated surfaces, 2D and 3D"),
    ("stereo", "calibration, matching and triangulation with two cameras"),
    ("mpm3d", "multiphoton z-stacks: lumen surface, height map, fold metrics"),
    ("multimodal", "camera and microscope together: fold-aware strain"),
    ("sample_data_synth", "synthetic videos, stacks and stereo scenes with exact truth"),
    ("tissue_napari", "the napari plugin: readers of videos, stacks and run folders; widgets"),
)


def public_modules(package: str) -> list[str]:
    """Dotted names of the package's public modules (its ``__init__`` first)."""
    base = ROOT / package
    names = []
    for path in sorted(base.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if parts[-1] == "__main__" or any(p.startswith("_") for p in parts):
            continue
        names.append(".".join(parts))
    return sorted(names, key=lambda n: (n.count("."), n))


def page(package: str, about: str) -> str:
    lines = [f"# `{package}`", "", f"{about[0].upper()}{about[1:]}.", ""]
    for name in public_modules(package):
        lines += [f"## `{name}`", "", f"::: {name}", "    options:", "      heading_level: 3", ""]
    return "\n".join(lines)


def main() -> int:
    out = ROOT / "docs" / "api"
    out.mkdir(exist_ok=True)
    for package, about in PACKAGES:
        text = page(package, about)
        path = out / f"{package}.md"
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Small synthetic MPM stacks (before / after contraction) with their truth, written once."""

import contextlib
import csv
import io
import json
import sys

import pytest

from sample_data_synth import make_stack_case, save_stack_truth, write_stack
from tests.mpm3d.helpers import cli


@pytest.fixture(scope="session")
def mpm_pair(tmp_path_factory):
    """``{"before": (path, case), "after": (path, case)}``: 256 x 256 px of 5 um, 4 um z-step."""
    folder = tmp_path_factory.mktemp("mpm")
    out = {}
    for name in ("before", "after"):
        case = make_stack_case(name, size=256, spacing=(4.0, 5.0, 5.0), rng=1)
        path = folder / f"{name}.tif"
        write_stack(path, case)
        save_stack_truth(folder / name, case)
        out[name] = (path, case)
    return out


@pytest.fixture(scope="session")
def mpm_small(tmp_path_factory):
    """``(path, case)``: a 96 x 96 px "before" stack (5 um pixels, 4 um z-step), ImageJ."""
    folder = tmp_path_factory.mktemp("mpm_small")
    case = make_stack_case("before", size=96, spacing=(4.0, 5.0, 5.0), rng=1)
    path = folder / "small.tif"
    write_stack(path, case)
    return path, case


@pytest.fixture(scope="session")
def after_run(mpm_pair, tmp_path_factory):
    """One full ``analyze after.tif`` (surface and figures), shared by the tests below."""
    path, case = mpm_pair["after"]
    out = tmp_path_factory.mktemp("analyze") / "after_out"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        status = cli("analyze", path, "--out", out)
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    return {
        "status": status,
        "path": path,
        "out": out,
        "case": case,
        "stderr": err.getvalue(),
        "m": metrics,
    }


@pytest.fixture(scope="session")
def compared(mpm_pair, tmp_path_factory):
    """One ``compare before.tif after.tif`` (figures, no isosurfaces), open3d missing."""
    out = tmp_path_factory.mktemp("compare") / "cmp"
    err = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err):
        mp.setitem(sys.modules, "open3d", None)
        before, after = mpm_pair["before"][0], mpm_pair["after"][0]
        status = cli("compare", before, after, "--out", out, "--no-surface", "-q")
    report = json.loads((out / "compare.json").read_text(encoding="utf-8"))
    with open(out / "changes.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return {"status": status, "out": out, "stderr": err.getvalue(), "report": report, "rows": rows}

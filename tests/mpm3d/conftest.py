"""Small synthetic MPM stacks (before / after contraction) with their truth, written once."""

import pytest

from sample_data_synth import make_stack_case, save_stack_truth, write_stack


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

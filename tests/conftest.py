import os

import pytest

# Never open windows or pick an interactive backend in tests.
os.environ.setdefault("MPLBACKEND", "Agg")
# Qt (the napari plugin's tests) draws off screen: no display needed
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

# Property tests draw the same examples on every machine, so `make test` gives the same answer
# in CI as on the developer's machine. To search for new failures, run
#   pytest --hypothesis-profile=explore tests/
# (random examples, five times as many) and add what it finds as an @example.
from hypothesis import settings

settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, max_examples=500, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


@pytest.fixture
def computed_blocks(monkeypatch) -> list[int]:
    """The frame counts of the blocks streamed strain fields compute from now on, in order."""
    from surface_strain import streamed

    computed: list[int] = []
    original = streamed._strain_field

    def counting(setup, points, visible):
        computed.append(len(points))
        return original(setup, points, visible)

    monkeypatch.setattr(streamed, "_strain_field", counting)
    return computed


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """``--dist loadgroup`` (make test): keep each ``xdist_group``'s tests on one worker.

    pytest-xdist names a grouped test ``NODEID@GROUP`` and schedules by that name, so that a
    group's tests (and the module fixtures they share) run once, in one worker.  It writes the
    name into ``item._nodeid``, which pytest 9.2 no longer reads (a node's id is ``item._id``):
    the marks were ignored and each group's fixtures made on every worker.  Where xdist's
    own suffix is missing, it is added here the way pytest now reads it; where xdist's works,
    nothing is done.
    """
    if not getattr(config.option, "loadgroup", False):
        return
    for item in items:
        names = {
            str(mark.args[0] if mark.args else mark.kwargs.get("name", "default"))
            for mark in item.iter_markers("xdist_group")
        }
        nodeid = item.nodeid
        if not names or nodeid.rfind("@") > nodeid.rfind("]"):  # ungrouped, or xdist's works
            continue
        node_id = getattr(item, "_id", None)
        if node_id is None or not hasattr(type(node_id), "parse"):  # another pytest: leave it
            continue
        item._id = type(node_id).parse(f"{nodeid}@{'_'.join(sorted(names))}")


def pytest_addoption(parser):
    """The options napari's viewer fixture reads: its pytest plugin is off (``-p
    no:napari``, it imports napari around every test) and tests/tissue_napari imports the
    fixture itself."""
    parser.addoption("--show-napari-viewer", action="store_true", default=False)
    parser.addoption("--save-leaked-object-graph", action="store_true", default=False)

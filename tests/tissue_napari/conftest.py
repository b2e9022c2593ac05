"""napari's own viewer fixture (``make_napari_viewer``, headless: QT_QPA_PLATFORM is
offscreen), taken from its pytest plugin, which is off for the rest of the suite."""

import warnings

import pytest

# napari's fixtures: the viewer, the app model it needs, and its clean-up of themes and
# Qt warnings (autouse here, as in napari's plugin); importing napari warns about its own
# dependencies' deprecations
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from napari.utils._testsupport import (  # noqa: F401
        _clean_themes,
        _disable_qt_warnings,
        make_napari_viewer,
        mock_app_model,
        pytest_runtest_makereport,  # the fixture reads each phase's report from the item
    )

#: napari and its Qt stack warn about their own dependencies' deprecations
THIRD_PARTY = [
    "ignore::DeprecationWarning",
    "ignore::PendingDeprecationWarning",
    "ignore::FutureWarning",
    "ignore:.*QOpenGLWidget.*:UserWarning",
]


def pytest_collection_modifyitems(items):
    for item in items:
        if "tissue_napari" in str(item.fspath):
            for rule in THIRD_PARTY:
                item.add_marker(pytest.mark.filterwarnings(rule))

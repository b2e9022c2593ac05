"""The report check itself: Chromium finds a broken image and a table wider than the page.

Every package's report test renders its ``report.html`` with
:func:`tests.report_browser.problems` and asserts there are none
(strain2d's run and study reports, mpm3d's analyze and compare reports,
stereo reconstruct's and surface_strain compute's).  These tests prove the
check can fail, and that the shared report builder keeps wide tables on the page.
"""

import base64

from tests.report_browser import check_report, problems
from tissue_core.html import HtmlReport

# a 1x1 PNG
_PIXEL = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQAAAABJRU5ErkJggg=="
)


def test_the_check_finds_a_broken_image_and_a_wide_table(tmp_path):
    bad = tmp_path / "bad.html"
    cells = "".join(f"<td>{'x' * 30}{i}</td>" for i in range(40))
    bad.write_text(
        '<html><body><img src="data:image/png;base64,AAAA" alt="broken figure">'
        f'<table style="white-space: nowrap"><tr>{cells}</tr></table></body></html>'
    )
    found = problems(bad)
    assert any("image does not render: broken figure" in p for p in found)
    assert any("table wider than the 1024px window" in p for p in found)
    assert any("page scrolls sideways" in p for p in found)


def test_reports_built_with_the_shared_builder_fit_the_page(tmp_path):
    png = tmp_path / "figure.png"
    png.write_bytes(_PIXEL)
    doc = HtmlReport("A report with a wide table")
    columns = [f"a_rather_long_column_name_{i}" for i in range(16)]
    doc.table([{c: 1234.5678 * i for i, c in enumerate(columns)}] * 3)
    doc.key_values({"sha256": "f" * 64, "command": "strain2d analyze " + "x" * 300})
    doc.media(png, "one pixel")
    doc.provenance({"long": ["y" * 200]})
    path = tmp_path / "report.html"
    doc.write(path)
    assert problems(path) == []
    seen = check_report(path)
    assert seen["figures"] == 1 and seen["images"] == []

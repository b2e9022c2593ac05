"""Render a ``report.html`` in headless Chromium and say what a reader would see broken.

:func:`check_report` loads a copy of the report with a small script added that
runs once the page has loaded, in a window ``width`` CSS pixels wide, and
returns what it found:

* ``images``: images that did not decode (``naturalWidth == 0``), by alt text;
* ``wide``: tables whose right edge is past the window (the reader would have
  to scroll sideways), with their width;
* ``page``: the document's scroll width against the window's width.

:func:`screenshot` writes a PNG of the top of a report (the README's pictures).
Both need Chromium (Debian's ``chromium``; ``make`` installs it where it can).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

__all__ = ["check_report", "chromium", "problems", "screenshot"]

_PROBE = """<script>
window.addEventListener('load', () => {
  const w = document.documentElement.clientWidth;
  const out = {images: [], wide: [], videos: 0, figures: 0};
  for (const img of document.images) {
    if (!img.complete || img.naturalWidth === 0) out.images.push(img.alt || img.src.slice(0, 60));
  }
  for (const t of document.querySelectorAll('table')) {
    const r = t.getBoundingClientRect();
    if (r.right > w + 0.5 || r.left < -0.5) {
      out.wide.push({rows: t.rows.length, width: Math.round(r.width),
                     first: (t.rows[0] ? t.rows[0].innerText : '').slice(0, 80)});
    }
  }
  out.videos = document.querySelectorAll('video').length;
  out.figures = document.querySelectorAll('figure').length;
  out.page = {scroll: document.documentElement.scrollWidth, window: w};
  const pre = document.createElement('pre');
  pre.id = 'report-browser-check';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""

_RESULT = re.compile(r'<pre id="report-browser-check">(.*?)</pre>', re.S)


def chromium() -> str:
    """The Chromium executable, or AssertionError saying how to install it."""
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        found = shutil.which(name)
        if found:
            return found
    raise AssertionError(
        "Chromium is needed to check the reports: sudo apt-get install -y chromium "
        "(make installs it when run as root)"
    )


def _run(args: list[str], timeout: float = 120) -> str:
    with tempfile.TemporaryDirectory() as profile:
        cmd = [
            chromium(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--no-first-run",
            f"--user-data-dir={profile}",
            *args,
        ]
        done = subprocess.run(
            cmd, capture_output=True, text=True, timeout=timeout, env={**os.environ, "LANG": "C"}
        )
    return done.stdout


def check_report(path: str | os.PathLike, *, width: int = 1024) -> dict:
    """What a reader of ``path`` sees broken in a ``width``-pixel window (see module doc)."""
    html = Path(path).read_text(encoding="utf-8")
    if "</body>" not in html:
        raise AssertionError(f"{path}: no </body>")
    with tempfile.TemporaryDirectory() as tmp:
        probe = Path(tmp) / "report.html"
        probe.write_text(html.replace("</body>", _PROBE + "</body>", 1), encoding="utf-8")
        dom = _run(
            [
                f"--window-size={width},900",
                "--virtual-time-budget=10000",
                "--dump-dom",
                probe.as_uri(),
            ]
        )
    found = _RESULT.search(dom)
    if found is None:
        raise AssertionError(f"{path}: Chromium did not run the page's check")
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


def problems(path: str | os.PathLike, *, width: int = 1024) -> list[str]:
    """The check as sentences; empty when the report renders whole and fits the window."""
    seen = check_report(path, width=width)
    out = [f"image does not render: {name}" for name in seen["images"]]
    out += [
        f"table wider than the {width}px window ({t['width']}px): {t['first']!r}"
        for t in seen["wide"]
    ]
    if seen["page"]["scroll"] > seen["page"]["window"]:
        out.append(f"page scrolls sideways ({seen['page']['scroll']}px in {width}px)")
    return out


def screenshot(path: str | os.PathLike, out: str | os.PathLike, *, size=(1100, 1400)) -> Path:
    """A PNG of the top ``size`` (width, height) CSS pixels of the report."""
    out = Path(out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    _run(
        [
            f"--window-size={size[0]},{size[1]}",
            "--virtual-time-budget=10000",
            f"--screenshot={out}",
            Path(path).resolve().as_uri(),
        ]
    )
    if not out.is_file():
        raise AssertionError(f"Chromium wrote no screenshot of {path}")
    return out

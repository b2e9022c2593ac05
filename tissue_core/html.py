"""A small builder for self-contained HTML reports (no external files, readable offline).

Images are embedded as base64 ``data:`` URIs (PNG, GIF, JPEG) or inline SVG,
videos (MP4) as a ``<video>`` element with a ``data:`` source; every piece of
text is escaped.  Every package's ``report.html`` is built with it, so the
reports look alike: the inputs with their checksums (:func:`input_records`),
parameters, results with units, figures, the quality of the measurement, what
was flagged, and the provenance folded away at the end.  The page is valid
UTF-8 whatever the names it shows: bytes of a file name that are not UTF-8
appear as ``\\xNN`` (:func:`tissue_core.filenames.readable`).

Tables fit the page: cells wrap (long names and checksums break anywhere) and
tables with many columns are set smaller, so no report is wider than the
browser window (``tests/test_report_browser.py`` checks it in Chromium).

Examples
--------
>>> doc = HtmlReport("A run")
>>> doc.paragraph("Exx < Eyy")
>>> doc.table([{"component": "Exx", "mean": -0.2}])
>>> "&lt;" in doc.html() and "<table" in doc.html()
True
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from tissue_core.filenames import readable
from tissue_core.outputs import sha256_of

__all__ = ["HtmlReport", "format_value", "input_records", "sequence_record"]

_MIME = {
    ".png": "image/png",
    ".gif": "image/gif",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".mp4": "video/mp4",
}

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 1100px; padding: 0 1em; color: #1d1d1f; line-height: 1.45; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { margin-top: 1.8em; border-bottom: 1px solid #ddd; }
.subtitle { color: #555; margin-top: 0; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; max-width: 100%; }
table.wide { font-size: 0.78em; } table.wide th, table.wide td { padding: 0.2em 0.35em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top;
         overflow-wrap: anywhere; }
th { background: #f2f2f2; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1.2em 0; } figure img, figure video, figure svg { max-width: 100%; height: auto; }
figcaption { color: #444; font-size: 0.92em; margin-top: 0.3em; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.note { background: #fff8e1; border-left: 4px solid #f0b400; padding: 0.5em 0.8em; }
.ok { background: #eef8ee; border-left: 4px solid #3a9a3a; padding: 0.5em 0.8em; }
details { margin: 1em 0; } details > summary { cursor: pointer; font-weight: 600; }
code { overflow-wrap: anywhere; }
.summary li { margin-bottom: 0.4em; }
"""


def format_value(value, digits: int = 4) -> str:
    """A table cell: numbers to ``digits`` significant figures, lists joined."""
    if isinstance(value, bool) or value is None:
        return "" if value is None else str(value).lower()
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "n/a"
        if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
            return f"{value:.{digits - 1}e}"
        return f"{value:.{digits}g}"
    if isinstance(value, list | tuple):
        return ", ".join(format_value(v, digits) for v in value)
    return str(value)


def _json_text(data, indent: int | None = 2) -> str:
    """``data`` as JSON to show (text as it is, not ``\\u`` escapes: the page is UTF-8)."""
    return json.dumps(data, indent=indent, default=str, allow_nan=True, ensure_ascii=False)


def _size_text(n) -> str:
    if not isinstance(n, int):
        return ""
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return ""


def input_records(paths: Iterable[str | os.PathLike]) -> list[dict]:
    """``[{"path", "bytes", "sha256", "files"}]`` for each input, for summaries and reports.

    A folder (of images, say) is one record: its regular files in name order
    hashed as one stream, with their count.  A path that cannot be read is
    recorded with ``sha256: None`` rather than failing the run that used it.
    """
    out = []
    for raw in paths:
        path = Path(raw)
        try:
            if path.is_dir():
                files = sorted(
                    p for p in path.iterdir() if p.is_file() and not p.name.startswith(".")
                )
                sha, size = sha256_of(files)
                out.append({"path": str(raw), "bytes": size, "sha256": sha, "files": len(files)})
            else:
                sha, size = sha256_of([path])
                out.append({"path": str(raw), "bytes": size, "sha256": sha, "files": 1})
        except OSError:
            out.append({"path": str(raw), "bytes": None, "sha256": None, "files": 0})
    return out


def sequence_record(paths: Sequence[str | os.PathLike]) -> dict:
    """One record for files read as one input in order (an image sequence), hashed as one stream.

    ``path`` names the first and the last file and the count.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise ValueError("sequence_record needs at least one path")
    if len(paths) == 1:
        return input_records(paths)[0]
    name = f"{paths[0]} ... {paths[-1].name}"
    try:
        sha, size = sha256_of(paths)
    except OSError:
        return {"path": name, "bytes": None, "sha256": None, "files": len(paths)}
    return {"path": name, "bytes": size, "sha256": sha, "files": len(paths)}


class HtmlReport:
    """An HTML document built section by section, written as one self-contained file."""

    def __init__(self, title: str, *, subtitle: str = "") -> None:
        self.title = title
        self._parts: list[str] = [f"<h1>{html.escape(title)}</h1>"]
        if subtitle:
            self._parts.append(f'<p class="subtitle">{html.escape(subtitle)}</p>')

    def heading(self, text: str, level: int = 2) -> None:
        self._parts.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, *, css: str = "") -> None:
        cls = f' class="{css}"' if css else ""
        self._parts.append(f"<p{cls}>{html.escape(text)}</p>")

    def bullets(self, items: Iterable[str], *, css: str = "") -> None:
        cls = f' class="{css}"' if css else ""
        rows = "".join(f"<li>{html.escape(t)}</li>" for t in items)
        self._parts.append(f"<ul{cls}>{rows}</ul>")

    def table(
        self,
        rows: Sequence[dict],
        *,
        columns: Sequence[str] | None = None,
        headers: Sequence[str] | None = None,
        digits: int = 4,
    ) -> None:
        """A table of dicts (one per row); ``columns`` picks and orders the keys."""
        if not rows:
            self.paragraph("(no rows)")
            return
        columns = list(columns or rows[0].keys())
        headers = list(headers or columns)
        head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
        wide = ' class="wide"' if len(columns) > 7 else ""
        body = []
        for row in rows:
            cells = []
            for c in columns:
                v = row.get(c)
                num = isinstance(v, int | float) and not isinstance(v, bool)
                cls = ' class="num"' if num else ""
                cells.append(f"<td{cls}>{html.escape(format_value(v, digits))}</td>")
            body.append("<tr>" + "".join(cells) + "</tr>")
        self._parts.append(f"<table{wide}><tr>{head}</tr>{''.join(body)}</table>")

    def key_values(self, mapping: dict, *, digits: int = 6) -> None:
        """A two-column table of a flat dict (nested values shown as JSON)."""
        rows = []
        for k, v in mapping.items():
            nested = isinstance(v, dict) or (
                isinstance(v, list) and any(isinstance(x, dict) for x in v)
            )
            text = _json_text(v, indent=None) if nested else format_value(v, digits)
            rows.append(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(text)}</td></tr>")
        self._parts.append(f"<table>{''.join(rows)}</table>")

    def code(self, text: str) -> None:
        self._parts.append(f"<pre>{html.escape(text)}</pre>")

    def json_block(self, data) -> None:
        self.code(_json_text(data))

    def flags(self, items: Sequence[str], *, none: str = "Nothing was flagged.") -> None:
        """What the run flagged, one warning box per item, or one line saying there was none."""
        if not items:
            self.paragraph(none, css="ok")
        for text in items:
            self.paragraph(text, css="note")

    def inputs(self, records: Sequence[dict]) -> None:
        """The input files with their size and SHA-256 (records from :func:`input_records`)."""
        rows = [
            {
                "input": r.get("path", "?"),
                "size": _size_text(r.get("bytes")),
                "SHA-256": r.get("sha256") or "",
                "files": r.get("files", 1),
            }
            for r in records
        ]
        columns = ["input", "size", "SHA-256"]
        if any(r["files"] != 1 for r in rows):
            columns.insert(1, "files")
        self.table(rows, columns=columns)

    def provenance(self, data, title: str = "Parameters and provenance (summary.json)") -> None:
        """``data`` as JSON, folded away under ``title`` (opened with a click)."""
        text = html.escape(_json_text(data))
        self._parts.append(
            f"<details><summary>{html.escape(title)}</summary><pre>{text}</pre></details>"
        )

    def media(self, path: str | os.PathLike, caption: str = "", *, alt: str = "") -> None:
        """Embed an image (PNG, GIF, JPEG, SVG) or an MP4 video from a file."""
        path = Path(path)
        suffix = path.suffix.lower()
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        alt = html.escape(alt or caption or path.name, quote=True)
        if suffix == ".svg":
            svg = path.read_text(encoding="utf-8")
            start = svg.find("<svg")
            self._parts.append(f"<figure>{svg[start:] if start >= 0 else svg}{cap}</figure>")
            return
        if suffix not in _MIME:
            raise ValueError(f"cannot embed {path.name}: use PNG, GIF, JPEG, SVG or MP4")
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        uri = f"data:{_MIME[suffix]};base64,{data}"
        if suffix == ".mp4":
            element = (
                f'<video controls loop muted playsinline title="{alt}">'
                f'<source src="{uri}" type="video/mp4"></video>'
            )
        else:
            element = f'<img src="{uri}" alt="{alt}">'
        self._parts.append(f"<figure>{element}{cap}</figure>")

    def html(self) -> str:
        """The whole page, valid UTF-8 (names that are not UTF-8 shown with ``\\xNN``)."""
        body = "\n".join(self._parts)
        return readable(
            '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{html.escape(self.title)}</title>\n<style>{_CSS}</style>\n</head>\n"
            f"<body>\n{body}\n</body>\n</html>\n"
        )

    def write(self, path: str | os.PathLike) -> None:
        Path(path).write_text(self.html(), encoding="utf-8")

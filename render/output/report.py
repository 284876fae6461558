"""A self-contained run report: one HTML page linking every image, video, table and plot of a run.

The page uses relative links to local files only, so it works offline and can be zipped with the
run folder. A small inline script counts media that failed to load and writes the count into
``<body data-missing=...>``, which the tests read back from headless Chromium.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Iterable
from pathlib import Path

from common.atomic import write_text_atomic

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".svg"}
VIDEO_SUFFIXES = {".mp4", ".webm"}
TABLE_SUFFIXES = {".md", ".csv"}

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
h1 { border-bottom: 2px solid #888; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; max-width: 560px; }
figure img, figure video { max-width: 560px; max-height: 480px; border: 1px solid #ccc; image-rendering: pixelated; }
figcaption { font-size: 0.85em; color: #555; }
caption { caption-side: bottom; font-size: 0.8em; color: #555; text-align: left; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0; }
td, th { border: 1px solid #bbb; padding: 2px 6px; text-align: right; }
pre { background: #f5f5f5; padding: 0.5em; overflow-x: auto; font-size: 0.8em; }
.files { font-size: 0.85em; columns: 3; }
.disagrees, .disagrees td { background: #fbd5d5; color: #8b0000; font-weight: bold; }
"""

SCRIPT = """
window.addEventListener('load', function () {
  var missing = 0;
  document.querySelectorAll('img').forEach(function (img) {
    if (!img.complete || img.naturalWidth === 0) { missing += 1; img.dataset.missing = '1'; }
  });
  var videos = document.querySelectorAll('video');
  var pending = videos.length;
  function done() { document.body.dataset.missing = String(missing); }
  if (pending === 0) { done(); return; }
  videos.forEach(function (v) {
    function ok() { pending -= 1; if (pending === 0) done(); }
    function bad() { missing += 1; v.dataset.missing = '1'; ok(); }
    if (v.readyState >= 1) { ok(); } else {
      v.addEventListener('loadedmetadata', ok, { once: true });
      v.addEventListener('error', bad, { once: true });
      var source = v.querySelector('source'); if (source) source.addEventListener('error', bad, { once: true });
    }
  });
});
"""


def markdown_table_to_html(text: str) -> str:
    """Convert the pipe tables we write ourselves into HTML; other lines become paragraphs."""
    out: list[str] = []
    rows: list[list[str]] = []

    def flush() -> None:
        if rows:
            header, *body = rows
            out.append("<table><tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in header) + "</tr>")
            out.extend("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in body)
            out.append("</table>")
            rows.clear()

    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("|"):
            cells = [c.strip() for c in stripped.strip("|").split("|")]
            if all(set(c) <= set("-: ") for c in cells):
                continue
            rows.append(cells)
        else:
            flush()
            if stripped:
                out.append(f"<p>{html.escape(stripped.lstrip('#').strip())}</p>")
    flush()
    return "\n".join(out)


def _section(title: str, folder: Path, report_dir: Path) -> str:
    files = sorted(p for p in folder.rglob("*") if p.is_file() and not p.name.startswith("."))
    if not files:
        return ""
    parts = [f"<h2>{html.escape(title)}</h2>"]
    manifest = folder / "manifest.json"
    if manifest.exists():
        record = json.loads(manifest.read_text())
        parts.append(
            f"<p>Started {html.escape(str(record.get('started_utc', '?')))}, took {record.get('seconds', 0):.1f} s, "
            f"at revision <code>{html.escape(str(record.get('git_revision', '?')))}</code>.</p>"
        )
    rel = lambda p: html.escape(os.path.relpath(p, report_dir))  # noqa: E731
    media = []
    for p in files:
        if p.suffix in IMAGE_SUFFIXES:
            media.append(
                f'<figure><a href="{rel(p)}"><img src="{rel(p)}" alt="{html.escape(p.name)}"></a>'
                f"<figcaption>{html.escape(p.name)}</figcaption></figure>"
            )
        elif p.suffix in VIDEO_SUFFIXES:
            media.append(
                f'<figure><video controls loop muted preload="metadata" src="{rel(p)}"></video>'
                f'<figcaption><a href="{rel(p)}">{html.escape(p.name)}</a></figcaption></figure>'
            )
    parts.extend(media)
    for p in files:
        if p.suffix == ".md":
            parts.append(f"<h3>{html.escape(p.name)}</h3>" + markdown_table_to_html(p.read_text(encoding="utf-8")))
    links = "".join(
        f'<li><a href="{rel(p)}">{html.escape(p.relative_to(folder).as_posix())}</a> '
        f"({p.stat().st_size / 1024:.0f} KiB)</li>"
        for p in files
    )
    parts.append(f"<details><summary>all files</summary><ul class='files'>{links}</ul></details>")
    return "\n".join(parts)


def write_report(
    report_path: Path, run_root: Path, stage_names: Iterable[str], title: str, lead_html: str = ""
) -> Path:
    """Write ``report_path``: ``lead_html`` first (the key results), then one section per finished stage
    folder under ``run_root``."""
    report_dir = report_path.parent
    sections = []
    for name in stage_names:
        folder = run_root / name
        if folder.is_dir():
            sections.append(_section(name, folder, report_dir))
    own = _section("this stage", report_dir, report_dir) if report_dir.is_dir() else ""
    body = "\n".join(s for s in [lead_html] + sections + [own] if s)
    return write_text_atomic(report_path, html_page(title, body))


def html_page(title: str, body: str) -> str:
    """The one page skeleton of every HTML file we write: title, style sheet and the media check."""
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{STYLE}</style><script>{SCRIPT}</script></head>"
        f"<body data-missing='pending'><h1>{html.escape(title)}</h1>\n{body}\n</body></html>\n"
    )

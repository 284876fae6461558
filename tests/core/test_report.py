"""The run report opens in headless Chromium with every image and video loading."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from pipeline.schema.composite import CompositeConfig
from render.output.composite import streak_images, transient_videos
from render.output.files import FrameAxis
from render.output.report import markdown_table_to_html, write_report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def chromium_dom(page, screenshot=None) -> str:
    # --run-all-compositor-stages-before-draw hangs with <video> elements here; keep flags minimal.
    args = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000"]
    if screenshot is not None:
        subprocess.run(
            args + ["--window-size=1280,1600", f"--screenshot={screenshot}", page.as_uri()],
            capture_output=True,
            timeout=60,
            check=True,
        )
    result = subprocess.run(
        args + ["--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=60, check=True
    )
    return result.stdout


def make_run(root):
    frames = np.zeros((6, 16, 16, 3), dtype=np.float32)
    for k in range(6):
        frames[k, 8, 2 * k : 2 * k + 3] = 1.0
    composite = root / "composite"
    composite.mkdir(parents=True)
    cfg = CompositeConfig(video_min_height=64)
    transient_videos(frames, FrameAxis(0.0, 0.003), cfg, composite)
    streak_images(frames, FrameAxis(0.0, 0.003), cfg, composite)
    (composite / "table.md").write_text("| renderer | relMSE |\n|---|---|\n| ours | 0.01 |\n")
    return composite


def test_markdown_tables_become_html():
    html_text = markdown_table_to_html("# Title\n| a | b |\n|---|---|\n| 1 | 2 |\n")
    assert "<th>a</th>" in html_text and "<td>2</td>" in html_text and "<p>Title</p>" in html_text


@pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (Debian package 'chromium'); `make setup` installs it"
)
def test_report_opens_in_chromium_without_missing_media(tmp_path):
    make_run(tmp_path / "run")
    report = write_report(tmp_path / "run" / "compare" / "report.html", tmp_path / "run", ["composite"], "test run")
    dom = chromium_dom(report, screenshot=tmp_path / "report.png")
    assert re.search(r'data-missing="0"', dom), dom[:500]
    assert dom.count("<video") == 2 and dom.count("<img") == 2
    assert (tmp_path / "report.png").stat().st_size > 5000
    # The check can fail: remove one image and the page reports it missing.
    (tmp_path / "run" / "composite" / "streak_x.png").unlink()
    report = write_report(tmp_path / "run" / "compare" / "report.html", tmp_path / "run", ["composite"], "test run")
    (tmp_path / "run" / "composite" / "streak_y.png").unlink()
    dom = chromium_dom(report)
    assert re.search(r'data-missing="1"', dom)

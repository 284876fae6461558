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


def test_the_report_opens_with_the_results_in_words_and_shows_no_raw_json(tmp_path):
    import json

    from render.output.compare import run_compare_stage

    run = tmp_path / "run"
    ours, ref = run / "render", run / "reference"
    ours.mkdir(parents=True)
    ref.mkdir()
    steady = np.full((4, 6, 3), 2.0, np.float32)
    frames = np.full((5, 4, 6, 3), 0.4, np.float32)
    np.save(ours / "steady.npy", steady * np.float32([0.98, 1.0, 1.02]))
    np.save(ours / "frames.npy", frames / 0.1)  # gate: densities per metre; bins of 0.1 m
    stats = {
        "frame_mode": "gate",
        "start_opl_m": 3.0,
        "bin_width_opl_m": 0.1,
        "temporal_bins": 5,
        "time_total_s": 12.5,
        "iterations": 64,
        "peak_memory_mib": 300.0,
        "accel_references": 123,
    }
    (ours / "stats.json").write_text(json.dumps(stats))
    (ours / "manifest.json").write_text(json.dumps({"summary": {"false_positives": 7}, "seconds": 12.6}))
    np.save(ref / "steady.npy", steady)
    np.save(ref / "frames.npy", frames)
    timing = {
        "steady": {"seconds": 40.0, "spp": 512},
        "transient": {"seconds": 50.0, "spp": 256},
        "film": {"start_opl": 3.0, "bin_width_opl": 0.1, "temporal_bins": 5},
    }
    (ref / "timing.json").write_text(json.dumps(timing))
    run_compare_stage(run, ours, ref, run / "compare", ["reference", "render"], "test run")
    page = (run / "compare" / "report.html").read_text()
    results = page.index("<h2>Results</h2>")
    assert results < page.index("<h2>reference</h2>") < page.index("<h2>render</h2>")
    assert "mean radiance is 0.980 / 1.000 / 1.020 (R / G / B) of Mitsuba volpath&#x27;s" in page
    assert "carry 1.000 / 1.000 / 1.000 (R / G / B) of mitransient&#x27;s energy" in page
    assert "ours (PTPB): 64 iterations in 12.5 s, peak memory 300 MiB." in page
    assert "time [s]" in page and "W m⁻² sr⁻¹" in page
    assert "<pre>" not in page and "false_positives" not in page and "accel_references" not in page

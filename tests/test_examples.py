"""The scripts under examples/ run as a user would run them, and what they print holds."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_render_a_snow_block_from_python(tmp_path):
    run = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "render_a_snow_block.py"), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    # The plain settings dict got the render section's defaults: bins mode's alpha 4/5, 24 iterations.
    assert re.search(r"rendered 24 iterations in [0-9.]+ s; alpha 0\.800", run.stdout), run.stdout
    # Frames (bins) integrate the light inside the window: at most the steady image, and most of it here.
    fraction = float(re.search(r"frames hold ([0-9.]+) of the steady", run.stdout).group(1))
    assert 0.9 <= fraction <= 1.001, run.stdout
    assert (tmp_path / "frames.png").stat().st_size > 10_000

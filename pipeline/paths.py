"""Well-known locations of the project tree."""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[1]
CONFIGS_DIR = PROJECT_ROOT / "configs"
PRESETS_DIR = CONFIGS_DIR / "presets"
DEFAULT_RUNS_DIR = Path("runs")

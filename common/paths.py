"""Well-known locations of the project tree."""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[1]
# In a clone (and an editable install) configs/ sits at the root; a wheel carries it as pipeline/configs.
CONFIGS_DIR = PROJECT_ROOT / "configs"
if not CONFIGS_DIR.is_dir():
    CONFIGS_DIR = Path(__file__).resolve().parents[1] / "pipeline" / "configs"
PRESETS_DIR = CONFIGS_DIR / "presets"
OPTICS_PRESETS_DIR = PRESETS_DIR / "optics"
DEFAULT_RUNS_DIR = Path("runs")


def optics_preset_names() -> list[str]:
    """The optical presets a medium may name: the stems of ``configs/presets/optics/*.yaml``."""
    return sorted(p.stem for p in OPTICS_PRESETS_DIR.glob("*.yaml"))

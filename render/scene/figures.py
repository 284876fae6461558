"""The scene stage's own figure: where and when direct light first reaches what the camera sees.

It lives with the scene builder, which draws it while it times the film window, so that the scene
never reaches up into render.output for a plot.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.atomic import save_figure_atomic  # noqa: E402
from common.units import PS_PER_M_OPL  # noqa: E402


def arrival_map(first_arrival_opl: np.ndarray, path: Path, title: str) -> list[Path]:
    """Per-pixel OPL of the earliest direct light (NaN where the camera sees no lit surface), in ps."""
    fig, ax = plt.subplots(figsize=(6.5, 6.5 * first_arrival_opl.shape[0] / first_arrival_opl.shape[1] + 0.5))
    shown = ax.imshow(first_arrival_opl * PS_PER_M_OPL, cmap="viridis", interpolation="nearest")
    fig.colorbar(shown, ax=ax, label="first direct arrival (ps)", shrink=0.8)
    ax.set_title(title, fontsize=10)
    ax.axis("off")
    written = save_figure_atomic(fig, path)
    plt.close(fig)
    return written

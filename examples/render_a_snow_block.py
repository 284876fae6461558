"""Render a small block of snow lit by the low sun with our renderer, from Python, and plot frames.

    .venv/bin/python examples/render_a_snow_block.py [--out DIR]

Three steps, as in a notebook:
1. build a scene folder with the scene stage (render.scene.stage.run_scene_stage) from a SceneConfig:
   a 1 m block of translucent snow (thesis set 6, isotropic reduced form) on the ground's level,
   the sun at 20 degrees and a camera framing the block;
2. read it back with ``render.ptpb.load_scene`` and render it with a plain settings dict, whose
   missing keys take the defaults of the config's render section (docs/config-reference.md);
3. plot the steady image and four frames, with the time since first light, into ``DIR/frames.png``.
It prints what it rendered: the schedule the core used and how the frames' energy compares with the
steady image (the frames hold the light that arrives inside the film window).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.units import NS_PER_M_OPL  # noqa: E402
from pipeline.schema.scene import (  # noqa: E402
    CameraConfig,
    FilmConfig,
    MediumConfig,
    ObjectConfig,
    SceneConfig,
    SkyConfig,
    SunConfig,
)
from render.ptpb import load_scene, render  # noqa: E402
from render.scene.stage import run_scene_stage  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("runs/example"), help="output folder")
    args = parser.parse_args()

    scene_config = SceneConfig(
        media={"snow": MediumConfig(preset="thesis_set_6", form="isotropic_reduced", boundary="null")},
        objects=[ObjectConfig(name="block", shape="box", medium="snow", center=(0, 0, 0.5), size=(1, 1, 1))],
        sun=SunConfig(kind="directional", elevation_deg=20.0, azimuth_deg=150.0, irradiance=1000.0),
        sky=SkyConfig(radiance=0.0),
        camera=CameraConfig(view_azimuth_deg=200.0, view_elevation_deg=25.0, width=96, height=72),
        film=FilmConfig(mode="transient", temporal_bins=24, window="auto", window_tail_opl=2.0),
    )
    run_scene_stage(scene_config, args.out / "scene")
    scene = load_scene(args.out / "scene")

    result = render(scene, {"iterations": 24, "light_paths_per_iteration": 20000, "frame_mode": "bins", "seed": 1})
    stats = result.stats
    film = scene["film"]
    print(
        f"rendered {stats['iterations']} iterations in {stats['time_total_s']:.1f} s; "
        f"alpha {stats['alpha']:.3f}, R_0 {stats['initial_beam_radius_m'] * 100:.2f} cm"
    )
    in_window = result.frames.sum(axis=0).mean() / result.steady.mean()
    print(f"frames hold {in_window:.3f} of the steady image's energy (the rest arrives outside the window)")

    picks = np.linspace(0, len(result.frames) - 1, 4).round().astype(int)
    scale = float(np.percentile(result.steady, 99.5)) or 1.0
    fig, axes = plt.subplots(1, 5, figsize=(15, 3))
    axes[0].imshow(np.clip(result.steady / scale, 0, 1) ** (1 / 2.2))
    axes[0].set_title("steady")
    frame_scale = float(np.percentile(result.frames, 99.5)) or 1.0
    for ax, k in zip(axes[1:], picks):
        ax.imshow(np.clip(result.frames[k] / frame_scale, 0, 1) ** (1 / 2.2))
        ax.set_title(f"t = {(k + 0.5) * film['bin_width_opl'] * NS_PER_M_OPL:.2f} ns after first light")
    for ax in axes:
        ax.set_axis_off()
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "frames.png", dpi=100, bbox_inches="tight")
    print(f"wrote {args.out / 'frames.png'}")


if __name__ == "__main__":
    main()

"""Shared set-up of the pipeline tests that run real stages: a lit block of snow-like medium stands
in for the penitente field, so they need no geometry stage. Imported by name: pytest puts this
folder on sys.path."""

from __future__ import annotations

from pathlib import Path

import yaml


def block_config(
    runs: Path,
    *,
    name: str,
    seed: int,
    render: dict,
    reference: dict,
    g: float = 0.0,
    width: int = 24,
    height: int = 16,
    bins: int = 12,
) -> str:
    """The YAML of a run: a 2 x 2 x 1 m block (sigma_s 3.0/2.5/2.0, sigma_a 0.3/0.1/0.05 per m) under a
    directional sun at 60 deg, seen from 4 m at ``width`` x ``height`` pixels into ``bins`` bins."""
    return yaml.safe_dump(
        {
            "name": name,
            "seed": seed,
            "threads": 2,
            "runs_dir": str(runs),
            "scene": {
                "media": {"snow": {"coefficients": {"sigma_s": [3.0, 2.5, 2.0], "sigma_a": [0.3, 0.1, 0.05], "g": g}}},
                "objects": [
                    {"name": "block", "shape": "box", "medium": "snow", "center": [0, 0, -0.5], "size": [2, 2, 1]}
                ],
                "camera": {
                    "placement": "look_at",
                    "origin": [0, -4, 3],
                    "target": [0, 0, -0.3],
                    "width": width,
                    "height": height,
                    "fov": 45,
                },
                "sun": {"kind": "directional", "elevation_deg": 60, "azimuth_deg": 30, "irradiance": 100.0},
                "sky": {"radiance": 0.0},
                "film": {
                    "mode": "transient",
                    "temporal_bins": bins,
                    "window": "auto",
                    "window_tail_opl": 1.0,
                },
                "max_depth": 16,
            },
            "reference": reference,
            "render": {**render, "initial_beam_radius": {"value": 0.03, "unit": "m"}},
            "composite": {"video_min_height": 64},
        },
        sort_keys=False,
    )

"""Space before time: what a stage's large arrays will take on disk, against the free space there.

A stage that writes a film (the reference's and our render's ``frames.npy``, the reference's EXR
frames, the render's checkpoint) declares an estimate of its bytes (``Stage.writes``). The runner
adds the estimates of the stages it is about to run and refuses before the first of them when the
run folder's file system has less free space, and checks each stage again just before it starts,
since other processes share the disk. Small files (JSON, PNG, videos, meshes) are not counted.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from pathlib import Path

FLOAT32_BYTES = 4
RGB = 3


class NotEnoughSpace(RuntimeError):
    """The stages about to run would write more than the run folder's file system has free."""


def image_bytes(config) -> int:
    """One (H, W, 3) float32 image."""
    camera = config.scene.camera
    return camera.height * camera.width * RGB * FLOAT32_BYTES


def film_bytes(config) -> int:
    """One (T, H, W, 3) float32 frame stack (render/output/files.py), or 0 for a steady film."""
    if config.scene.film.mode != "transient":
        return 0
    return config.scene.film.temporal_bins * image_bytes(config)


def free_bytes(folder: Path) -> int:
    """Bytes free to this user on the file system of ``folder`` (or of its nearest existing parent)."""
    folder = Path(folder).absolute()
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return shutil.disk_usage(folder).free


def mib(n: int) -> str:
    return f"{n / 2**20:.1f} MiB"


def check_space(folder: Path, needs: Mapping[str, int], config) -> None:
    """Raise ``NotEnoughSpace`` when the ``needs`` (bytes by stage name, the stages not started yet) exceed
    the free space of ``folder``'s file system."""
    total = sum(needs.values())
    if total == 0:
        return
    free = free_bytes(folder)
    if total <= free:
        return
    camera, film = config.scene.camera, config.scene.film
    unit = mib if mib(total) != mib(free) else (lambda n: f"{n:,} bytes")  # figures that round alike
    parts = ", ".join(f"{name} {unit(n)}" for name, n in needs.items() if n)
    raise NotEnoughSpace(
        f"not enough free space in {folder}: the stages to run write about {unit(total)} ({parts}) and its file "
        f"system has {unit(free)} free, so {', '.join(needs)} did not start. Shrink the output "
        f"(scene.film.temporal_bins = {film.temporal_bins}, scene.camera.width x height = {camera.width} x "
        f"{camera.height}, reference.transient: false) or set runs_dir to a larger file system; "
        "render.memory_budget_gib bounds memory, not disk (its windows write the same frames.npy)"
    )


__all__ = ["NotEnoughSpace", "check_space", "film_bytes", "free_bytes", "image_bytes"]

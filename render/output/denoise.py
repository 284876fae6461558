"""Denoised delivery frames (render/output/LOOK.md, *Denoised delivery*): Intel Open Image Denoise (``pyoidn``, CPU) on each
transient frame, guided by the albedo and normal of the first camera hit (``Guides``, which
render.scene.guides traces from the scene's own triangles: noise-free and the same for every frame).

Denoised frames are for people to look at. Comparisons, guards, tables and the sweep summary read the raw
frames; nothing here writes over them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.atomic import atomic_path


@dataclass(frozen=True)
class Guides:
    """First-hit albedo [0, 1] and world-space unit normal (facing the camera) per pixel, (H, W, 3) float32."""

    albedo: np.ndarray
    normal: np.ndarray


def denoise_frame(frame: np.ndarray, guides: Guides, quality: str = "high") -> np.ndarray:
    """One (H, W, 3) linear frame through OIDN's ray-tracing filter in HDR mode with clean (noise-free)
    guides, then scaled per channel to the raw frame's sum. The network moves light between pixels but was not
    trained to keep a frame's energy (on the demo at 64 iterations it lost 1-4 % of late frames' light); the
    raw frame's sum is an unbiased estimate of it with far less noise than any pixel, so the denoised frame
    keeps it. An all-black frame stays black without a call."""
    import pyoidn

    if not np.any(frame):
        return np.zeros_like(frame, dtype=np.float32)
    color = np.ascontiguousarray(np.maximum(frame, 0.0), np.float32)
    out = np.maximum(
        np.asarray(
            pyoidn.denoise(color, guides.albedo, guides.normal, hdr=True, clean_aux=True, quality=quality), np.float64
        ),
        0.0,
    )
    raw_sum, out_sum = np.asarray(frame, np.float64).sum(axis=(0, 1)), out.sum(axis=(0, 1))
    scale = np.divide(raw_sum, out_sum, out=np.ones(3), where=out_sum > 0)
    return (out * np.maximum(scale, 0.0)).astype(np.float32)


def denoise_film(
    frames: np.ndarray, guides: Guides, path: Path, quality: str = "high", progress: bool = True
) -> np.ndarray:
    """Denoise a (T, H, W, 3) stack (in memory or memory-mapped) frame by frame into ``path`` (.npy), written to a
    temporary file and renamed when complete; returns the result memory-mapped."""
    from tqdm import tqdm

    path = Path(path)
    if frames.shape[1:3] != guides.albedo.shape[:2]:
        raise ValueError(
            f"frames are {frames.shape[2]}x{frames.shape[1]} pixels but the scene's camera is "
            f"{guides.albedo.shape[1]}x{guides.albedo.shape[0]}; run the scene and render stages again"
        )
    with atomic_path(path) as temporary:
        out = np.lib.format.open_memmap(temporary, mode="w+", dtype=np.float32, shape=frames.shape)
        for k in tqdm(range(frames.shape[0]), desc="denoise", unit="frame", disable=not progress, leave=False):
            out[k] = denoise_frame(np.asarray(frames[k], np.float32), guides, quality)
        out.flush()
        del out
    return np.load(path, mmap_mode="r")


def save_guides(guides: Guides, path: Path) -> Path:
    """``path`` (PNG): the albedo guide beside the normal guide (n/2 + 1/2, grey where nothing is hit), each at
    least 256 pixels wide."""
    from PIL import Image

    normal = np.where(np.any(guides.normal != 0, axis=2, keepdims=True), 0.5 * guides.normal + 0.5, 0.5)
    panel = np.concatenate([np.clip(guides.albedo, 0.0, 1.0), np.clip(normal, 0.0, 1.0)], axis=1)
    image = Image.fromarray((panel * 255 + 0.5).astype(np.uint8))
    zoom = max(1, -(-256 // guides.albedo.shape[1]))
    image = image.resize((image.width * zoom, image.height * zoom), Image.Resampling.NEAREST)
    with atomic_path(path) as temporary:
        image.save(temporary, format="PNG")
    return Path(path)


def temporal_roughness(frames: np.ndarray) -> float:
    """Frame-to-frame flicker of a stack [-]: the summed |second difference in time| of every pixel over the summed
    signal, sum |f[k+1] - 2 f[k] + f[k-1]| / sum |f|. Noise that changes from frame to frame raises it; a
    smooth wavefront moving through the frames keeps it low."""
    rough, total = 0.0, 0.0
    recent: list[np.ndarray] = []  # the two frames before this one
    for k in range(frames.shape[0]):
        frame = np.asarray(frames[k], np.float64)
        total += float(np.abs(frame).sum())
        if len(recent) == 2:
            rough += float(np.abs(frame - 2.0 * recent[1] + recent[0]).sum())
        recent = [*recent[-1:], frame]
    return rough / total if total > 0 else 0.0

"""The scene and the long reference render of benchmarks/bench_ptpb.py, cached on disk.

- ``bench_scene(config)`` builds the scene folder (scene.json, ptpb_scene.json, meshes) once per
  config: ``benchmarks/results/cache/scene-<hash of the scene section, the seed and the meshes>/``.
  Mesh paths in the config are relative to the config file's folder (pipeline/config.py).
- ``reference(scene_dir, cfg)`` renders mitransient's transient_prbvolpath at ``reference.transient_spp``
  as two independent halves (frames and its steady image) and keeps them in
  ``cache/reference-<hash>.npz``, keyed by the scene files, the spp, the tiles and the Mitsuba versions.
  It renders in ``reference.tiles`` tiles, as the reference stage does: untiled, Mitsuba's ray offsets put
  the dense cube's reference 1.8 % above ours and the tiled one (render/mitsuba/export.py). Two halves let
  the error of a render be corrected for the reference's own noise (``FrameError``).
  ``per_channel=True`` renders each colour channel on its own, the media grey at that channel's coefficients:
  in a chromatic medium mitransient draws free flights for one channel and weighs the others by ratios of
  their transmittances, which multiply over hundreds of collisions into a heavy tail that no affordable spp
  converges (the thesis row, benchmarks/README.md); transport is linear per channel, so the three grey
  renders' channels are the same estimate without that tail.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from common.atomic import atomic_path
from pipeline.config import config_hash
from render.output.metrics import RELMSE_EPSILON

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
CACHE = RESULTS / "cache"
REFERENCE_SEEDS = (1_000_000, 2_000_000)  # far from the seeds of the timed renders (0, 1, ...)

log = logging.getLogger(__name__)


def bench_scene(config) -> Path:
    """The scene folder of ``config`` (the scene stage), built on the first call and cached by the
    config's scene section, its seed and the mesh files it names."""
    from render.scene.stage import run_scene_stage

    h = hashlib.sha256(config_hash(config, ["scene", "seed"]).encode())
    for obj in config.scene.objects:
        if obj.path:
            h.update((REPO / obj.path).read_bytes())
    folder = CACHE / f"scene-{h.hexdigest()[:16]}"
    if (folder / "ptpb_scene.json").is_file():
        return folder
    print(f"building the benchmark scene in {folder} (once) ...", flush=True)
    staging = folder.with_name(folder.name + ".partial")
    shutil.rmtree(staging, ignore_errors=True)
    run_scene_stage(config.scene, staging)
    staging.rename(folder)
    return folder


def _scene_digest(scene_dir: Path) -> str:
    h = hashlib.sha256()
    for path in sorted([scene_dir / "scene.json", *(scene_dir / "meshes").glob("*.ply")]):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


@dataclass
class Reference:
    """The two halves of the reference (frames (T, H, W, 3), steady (H, W, 3)) and their render time."""

    frames: tuple[np.ndarray, np.ndarray]
    steady: tuple[np.ndarray, np.ndarray]
    spp: int
    seconds: float

    def frame_error(self) -> FrameError:
        return FrameError(*self.frames)

    def steady_error(self) -> FrameError:
        return FrameError(self.steady[0][None], self.steady[1][None])


def grey_channel(scene, channel: int):
    """``scene`` (render.scene.model.Scene) with every medium grey at its ``channel``'s sigma_s and sigma_a."""
    media = {
        name: dataclasses.replace(m, sigma_s=(m.sigma_s[channel],) * 3, sigma_a=(m.sigma_a[channel],) * 3)
        for name, m in scene.media.items()
    }
    return dataclasses.replace(scene, media=media)


def reference(scene_dir: Path, cfg, per_channel: bool = False) -> Reference:
    """mitransient at ``cfg.transient_spp`` (two halves), cached; ``cfg`` is the config's reference section
    (its ``rr_depth``, when set, replaces the scene's, as in the reference stage). ``per_channel``: one grey
    render per channel, each at that spp (module docstring)."""
    import mitsuba

    from render.mitsuba.export import disk_sun_opl_shift, use_variant
    from render.mitsuba.passes import render_transient
    from render.mitsuba.stage import reference_scene

    use_variant(transient=True)
    import mitransient

    spp = cfg.transient_spp or cfg.spp
    scene = reference_scene(scene_dir, cfg)
    key_text = json.dumps(
        {
            "scene": _scene_digest(scene_dir),
            "window_shift_opl": disk_sun_opl_shift(scene, scene_dir),  # the time axis the frames are on
            "spp": spp,
            # The film the reference renders on; keyed only when coarser, so full-size caches stay valid.
            **({"downsample": cfg.downsample} if cfg.downsample != 1 else {}),
            # Keyed only when tiled, so the untiled caches of earlier runs keep their keys.
            **({"tiles": cfg.tiles} if cfg.tiles else {}),
            **({"per_channel": True} if per_channel else {}),
            # An auto depth is keyed by the depth it resolved to; a set one as written, so old caches keep their keys.
            "rr_depth": scene.rr_depth if cfg.rr_depth == "auto" else cfg.rr_depth,
            "seeds": REFERENCE_SEEDS,
            "mitsuba": mitsuba.__version__,
            "mitransient": mitransient.__version__,
        }
    )
    path = CACHE / f"reference-{hashlib.sha256(key_text.encode()).hexdigest()[:16]}.npz"
    if path.is_file():
        with np.load(path) as z:
            return Reference(
                (z["frames_a"], z["frames_b"]), (z["steady_a"], z["steady_b"]), int(z["spp"]), float(z["seconds"])
            )
    what = f"{spp} spp{' a channel' if per_channel else ''}"
    print(f"rendering the reference: mitransient at {what}, cached in {path} (once; minutes) ...", flush=True)

    def run(s, seed: int) -> tuple[np.ndarray, np.ndarray]:
        frames, steady, _ = render_transient(
            s, scene_dir, spp=spp // 2, spp_per_pass=cfg.spp_per_pass, seed=seed, quiet=False, tiles=cfg.tiles
        )
        return frames, steady

    def half(seed: int) -> tuple[np.ndarray, np.ndarray]:
        if not per_channel:
            return run(scene, seed)
        grey = [run(grey_channel(scene, c), seed + c) for c in range(3)]
        frames = np.stack([g[0][..., c] for c, g in enumerate(grey)], axis=-1)
        steady = np.stack([g[1][..., c] for c, g in enumerate(grey)], axis=-1)
        return frames, steady

    halves = []
    t0 = time.perf_counter()
    for seed in REFERENCE_SEEDS:
        halves.append(half(seed))
    seconds = time.perf_counter() - t0
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(
                f,
                frames_a=halves[0][0],
                frames_b=halves[1][0],
                steady_a=halves[0][1],
                steady_b=halves[1][1],
                spp=spp,
                seconds=seconds,
                key=key_text,
            )
    return Reference((halves[0][0], halves[1][0]), (halves[0][1], halves[1][1]), spp, seconds)


class FrameError:
    """relMSE of renders against a two-half reference, with the reference's own noise taken out.

    relMSE(x) = mean over frames, pixels and channels of (x - r)^2 / (r^2 + 1e-2) (render/output/metrics.py),
    with r the mean of the halves a and b. Since x and r are independent, its expectation is the error
    of x plus the reference's variance term, estimated as mean((a - b)^2 / (r^2 + 1e-2)) / 4; the
    corrected figure subtracts it. Frames are equal in size, so the mean over all values is the mean of
    the per-frame relMSEs (``per_frame``, with ``frame_noise``, gives them one by one). The estimate is low
    where a pixel's light is rare: where both halves miss light of mean mu, the reference costs mu^2 / 1e-2
    but the halves agree (a = b = 0), so what is taken out is at most the reference's noise and the figures
    left are, if anything, high."""

    def __init__(self, a: np.ndarray, b: np.ndarray):
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
        self.halves = (a, b)
        self.reference = 0.5 * (a + b)
        self.weight = 1.0 / (self.reference**2 + RELMSE_EPSILON)
        self.frame_noise = self._per_frame((a - b) ** 2 * self.weight) / 4.0
        self.reference_noise = float(np.mean((a - b) ** 2 * self.weight) / 4.0)

    @staticmethod
    def _per_frame(values: np.ndarray) -> np.ndarray:
        return np.mean(values, axis=tuple(range(1, values.ndim)))

    def per_frame(self, x: np.ndarray) -> np.ndarray:
        """The corrected relMSE of every frame of x (the first axis), as a (T,) array."""
        x = np.asarray(x, np.float64).reshape(self.reference.shape)
        return self._per_frame((x - self.reference) ** 2 * self.weight) - self.frame_noise

    def seed_variance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Per frame, the variance of one render of an unbiased estimator, from two renders x and y of it with
        independent seeds: mean((x - y)^2 w) / 2, in the units of ``per_frame``. The reference's noise is that of
        one render divided by how many times longer it ran: the part its halves miss (rare light both missed) is
        that less ``frame_noise``."""
        x = np.asarray(x, np.float64).reshape(self.reference.shape)
        y = np.asarray(y, np.float64).reshape(self.reference.shape)
        return self._per_frame((x - y) ** 2 * self.weight) / 2.0

    def raw(self, x: np.ndarray) -> float:
        return float(
            np.mean((np.asarray(x, np.float64).reshape(self.reference.shape) - self.reference) ** 2 * self.weight)
        )

    def __call__(self, x: np.ndarray) -> float:
        return self.raw(x) - self.reference_noise

    def late(self, first: int) -> FrameError:
        """The same error over frames ``first`` on (call it with those frames of a render)."""
        return FrameError(self.halves[0][first:], self.halves[1][first:])

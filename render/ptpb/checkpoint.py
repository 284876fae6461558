"""Checkpoints of progressive PTPB renders: the core's accumulated state, saved atomically as one
``checkpoint.npz`` and read back only for the same scene and settings.

A checkpoint holds the sums (steady, early and late in float64, the frames in float32 with, past
10^4 iterations, their float32 rounding remainders ``frames_carry``), the counters and timings, the
steady snapshots, the completed iteration count, the bandwidths of the last iteration and the
seed. Random streams are keyed by (seed, iteration, index) (render/core/DESIGN.md §9), so a render resumed from
it ends with the same bits as one that was never interrupted.

Its fingerprint is the scene (meshes by SHA-256) and every setting that changes what an iteration
adds. The settings in RUN_ONLY_SETTINGS only decide how many iterations run, on how many threads,
how often checkpoints are saved or how much memory may be used, so they may change between the
interrupted run and the one that resumes it (a larger ``iterations`` continues the same render).
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from common.atomic import atomic_path

CHECKPOINT_NAME = "checkpoint.npz"
FORMAT_VERSION = 2  # 2: float32 frame sums (and frames_carry); 1 held float64 frames
RUN_ONLY_SETTINGS = (
    "iterations",
    "time_budget_s",
    "threads",
    "checkpoint_every_iterations",
    "checkpoint_every_s",
    "memory_budget_gib",
)
STATE_ARRAYS = ("steady", "early", "late", "frames")
OPTIONAL_ARRAYS = ("frames_carry",)  # present past the core's compensated_sums_from (10^4) iterations


def _canonical(value: Any) -> Any:
    """JSON-able form of a scene or settings value; arrays become their dtype, shape and SHA-256."""
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value)
        return {
            "dtype": str(data.dtype),
            "shape": list(data.shape),
            "sha256": hashlib.sha256(data.tobytes()).hexdigest(),
        }
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def render_fingerprint(scene: dict, core_settings: dict) -> dict:
    """What a checkpoint must match to be resumed: the scene's digest and the settings that shape an iteration."""
    film = scene.get("film", {})
    # The film's frame mode decides the core's default alpha, so it is named with the settings.
    scene_json = json.dumps(
        _canonical({**scene, "film": {k: v for k, v in film.items() if k != "frame_mode"}}),
        sort_keys=True,
        separators=(",", ":"),
    )
    settings = {k: _canonical(v) for k, v in sorted(core_settings.items()) if k not in RUN_ONLY_SETTINGS}
    return {
        "scene_sha256": hashlib.sha256(scene_json.encode("utf-8")).hexdigest(),
        "settings": {**settings, "frame_mode": film.get("frame_mode")},
    }


def differences(saved: dict, current: dict) -> list[str]:
    """Readable differences between two fingerprints; empty when a checkpoint may be resumed."""
    found = []
    if saved.get("scene_sha256") != current["scene_sha256"]:
        found.append("the scene (the scene stage's ptpb_scene.json or its meshes) changed")
    old, new = saved.get("settings", {}), current["settings"]

    def shown(settings: dict, key: str) -> str:
        # None leaves the value to the core's default for the frame mode (alpha, surface_alpha).
        return "(unset)" if key not in settings else "(default)" if settings[key] is None else repr(settings[key])

    for key in sorted(set(old) | set(new)):
        if old.get(key) != new.get(key):
            found.append(f"{key} {shown(old, key)} -> {shown(new, key)}")
    return found


def save_checkpoint(path: Path, state: dict, fingerprint: dict) -> Path:
    """Write the core's checkpoint ``state`` and its fingerprint atomically to ``path``."""
    meta = {
        "format": FORMAT_VERSION,
        "fingerprint": fingerprint,
        "stats": state["stats"],
        **{k: state[k] for k in ("width", "height", "frame_count", "seed")},
    }
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(
                handle,
                meta=np.array(json.dumps(meta, sort_keys=True)),
                snapshot_iterations=np.asarray(state["snapshot_iterations"], dtype=np.int64),
                snapshot_seconds=np.asarray(state["snapshot_seconds"], dtype=np.float64),
                snapshots=state["snapshots"],
                **{k: state[k] for k in (*STATE_ARRAYS, *OPTIONAL_ARRAYS) if k in state},
            )
    return Path(path)


def load_checkpoint(path: Path, fingerprint: dict) -> dict:
    """The state saved in ``path``, for the core's ``resume``; ValueError when it cannot be read or
    was saved for another scene or other settings (the message lists what differs)."""
    try:
        with np.load(path, allow_pickle=False) as saved:
            meta = json.loads(str(saved["meta"]))
            arrays = {k: saved[k] for k in (*STATE_ARRAYS, "snapshots", "snapshot_iterations", "snapshot_seconds")}
            arrays.update({k: saved[k] for k in OPTIONAL_ARRAYS if k in saved.files})
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: cannot read the checkpoint ({exc})") from None
    if meta.get("format") != FORMAT_VERSION:
        raise ValueError(f"{path}: checkpoint format {meta.get('format')!r}, this version reads {FORMAT_VERSION}")
    changed = differences(meta.get("fingerprint", {}), fingerprint)
    if changed:
        raise ValueError(
            f"{path} was saved by a render with another scene or other settings ({'; '.join(changed)}), "
            "so it cannot continue this one"
        )
    return {
        **{k: meta[k] for k in ("width", "height", "frame_count", "seed", "stats")},
        **{k: arrays[k] for k in (*STATE_ARRAYS, *OPTIONAL_ARRAYS, "snapshots") if k in arrays},
        "snapshot_iterations": arrays["snapshot_iterations"].tolist(),
        "snapshot_seconds": arrays["snapshot_seconds"].tolist(),
    }


__all__ = [
    "CHECKPOINT_NAME",
    "RUN_ONLY_SETTINGS",
    "render_fingerprint",
    "differences",
    "save_checkpoint",
    "load_checkpoint",
]

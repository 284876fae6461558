"""Checkpoints of the render stage: a render resumed from checkpoint.npz has the bytes of an
uninterrupted one; a checkpoint of another scene or other settings, or a damaged one, is refused
with what differs; settings that only decide how long or how a render runs may change."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from pipeline.schema.ptpb import BeamRadius, PTPBConfig
from render.ptpb.checkpoint import CHECKPOINT_NAME
from render.ptpb.stage import run_render_stage


def config(**kw) -> PTPBConfig:
    base = dict(
        iterations=6,
        light_paths_per_iteration=2000,
        snapshot_every=2,
        checkpoint_every_iterations=3,
        initial_beam_radius=BeamRadius(value=0.03, unit="m"),
    )
    base.update(kw)
    return PTPBConfig(**base)


def render_stage(scene_dir, cfg: PTPBConfig, out, *, seed: int, threads: int, checkpoint_dir):
    """The render stage with this test's seed and thread count (a pipeline takes them from the root)."""
    cfg = cfg.model_copy(update={"seed": seed, "threads": threads})
    return run_render_stage(scene_dir, cfg, out, quiet=True, checkpoint_dir=checkpoint_dir)


def digests(folder) -> dict[str, str]:
    return {name: hashlib.sha256((folder / name).read_bytes()).hexdigest() for name in ("frames.npy", "steady.npy")}


@pytest.mark.parametrize("frame_mode", ["bins", "gate"])
def test_a_render_resumed_from_its_checkpoint_has_the_bytes_of_an_uninterrupted_one(scene_dir, frame_mode):
    cfg = config(frame_mode=frame_mode)
    checkpoints = scene_dir / "checkpoints"
    # Called without the stage runner, nothing removes the checkpoint of iteration 3 of 6 ...
    whole = render_stage(scene_dir, cfg, scene_dir / "whole", seed=1, threads=2, checkpoint_dir=checkpoints)
    assert (checkpoints / CHECKPOINT_NAME).exists()
    # ... so a second call resumes from it, on another thread count, and renders iterations 4 to 6.
    resumed = render_stage(scene_dir, cfg, scene_dir / "resumed", seed=1, threads=1, checkpoint_dir=checkpoints)
    assert digests(scene_dir / "whole") == digests(scene_dir / "resumed")
    for key in ("iterations", "light_paths", "beams", "pair_evaluations", "surface_pairs", "final_radius"):
        assert resumed[key] == whole[key], key
    with np.load(scene_dir / "whole" / "snapshots.npz") as a, np.load(scene_dir / "resumed" / "snapshots.npz") as b:
        assert a["iterations"].tolist() == b["iterations"].tolist() == [2, 4, 6]
        assert np.array_equal(a["steady"], b["steady"])
        assert b["seconds"][0] == a["seconds"][0]  # the snapshot of iteration 2 came from the checkpoint


def test_more_iterations_or_threads_continue_the_same_render(scene_dir):
    checkpoints = scene_dir / "checkpoints"
    render_stage(scene_dir, config(), scene_dir / "six", seed=1, threads=2, checkpoint_dir=checkpoints)
    longer = config(iterations=8, checkpoint_every_iterations=0, memory_budget_gib=1.0)
    render_stage(scene_dir, longer, scene_dir / "resumed", seed=1, threads=1, checkpoint_dir=checkpoints)
    render_stage(scene_dir, longer, scene_dir / "fresh", seed=1, threads=2, checkpoint_dir=scene_dir / "none")
    assert digests(scene_dir / "resumed") == digests(scene_dir / "fresh")


def test_a_checkpoint_of_other_settings_or_another_scene_is_refused_naming_what_changed(scene_dir):
    checkpoints = scene_dir / "checkpoints"
    render_stage(scene_dir, config(), scene_dir / "a", seed=1, threads=2, checkpoint_dir=checkpoints)
    for cfg, seed, changed in [
        (config(alpha=0.7), 1, r"alpha \(default\) -> 0.7"),
        (config(), 2, "seed 1 -> 2"),
        (config(initial_beam_radius=BeamRadius(value=0.02, unit="m")), 1, "initial_beam_radius 0.03 -> 0.02"),
        (config(frame_mode="gate"), 1, "frame_mode 'bins' -> 'gate'"),
    ]:
        with pytest.raises(ValueError, match=f"other settings .*{changed}.*run without --resume"):
            render_stage(scene_dir, cfg, scene_dir / "b", seed=seed, threads=2, checkpoint_dir=checkpoints)
    scene = json.loads((scene_dir / "ptpb_scene.json").read_text())
    scene["media"][0]["g"] = 0.6
    (scene_dir / "ptpb_scene.json").write_text(json.dumps(scene))
    with pytest.raises(ValueError, match="the scene .* changed"):
        render_stage(scene_dir, config(), scene_dir / "b", seed=1, threads=2, checkpoint_dir=checkpoints)
    assert not (scene_dir / "b").exists()  # refused before anything was rendered or written


def test_a_damaged_checkpoint_is_refused(scene_dir):
    checkpoints = scene_dir / "checkpoints"
    checkpoints.mkdir()
    (checkpoints / CHECKPOINT_NAME).write_bytes(b"PK\x03\x04 not really a zip file")
    with pytest.raises(ValueError, match="cannot read the checkpoint"):
        render_stage(scene_dir, config(), scene_dir / "a", seed=1, threads=2, checkpoint_dir=checkpoints)

"""SIGKILL `python -m pipeline run` at seeded random moments: after every kill each visible stage
folder is complete (its manifest's outputs hash as recorded) and a checkpoint, if any, is whole;
the next run finishes with correct manifests, and a render resumed from a killed run's checkpoint
has the bits of an uninterrupted one."""

from __future__ import annotations

import hashlib
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from block_scene import block_config

from common.paths import PROJECT_ROOT
from pipeline.manifest import outputs_intact, read_manifest

STAGES = ("scene", "render", "composite", "compare")


def pipeline_command(config: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "pipeline", "run", str(config), "--quiet", *extra]


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def assert_nothing_half_written(run: Path) -> list[str]:
    """Every visible stage folder has a manifest whose outputs are intact; returns the complete stages."""
    complete = []
    for folder in sorted(p for p in run.iterdir() if p.is_dir() and not p.name.startswith(".")):
        manifest = read_manifest(folder)
        assert manifest is not None, f"{folder} is visible without a readable manifest"
        assert outputs_intact(folder, manifest), f"{folder}: an output does not match its manifest"
        assert set(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()) == set(
            manifest["outputs"]
        ) | {"manifest.json"}, f"{folder} holds files its manifest does not list"
        complete.append(folder.name)
    checkpoint = run / ".render.checkpoint" / "checkpoint.npz"
    if checkpoint.exists():
        import numpy as np

        with np.load(checkpoint, allow_pickle=False) as saved:  # whole: every array reads back
            assert saved["frames"].shape == (12, 16, 24, 3) and "meta" in saved.files
    return complete


def kill_and_check(config: Path, run: Path, kills: int, rng: random.Random, full_run_s: float) -> dict:
    """Kill ``kills`` runs at uniform random times within a whole run; alternate fresh and resumed runs."""
    seen: dict[str, int] = {}
    for k in range(kills):
        extra = ("--force", "--resume") if k % 2 else ("--force",)
        process = subprocess.Popen(
            pipeline_command(config, *extra),
            cwd=config.parent,
            start_new_session=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        time.sleep(rng.uniform(0.2, full_run_s))
        in_flight = [p.name.split(".")[1] for p in run.glob(f".*.staging-{process.pid}")] if run.exists() else []
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=30)
        for name in in_flight or ["(none)"]:
            seen[name] = seen.get(name, 0) + 1
        if run.exists():
            assert_nothing_half_written(run)
    return seen


def run_kill_test(tmp_path: Path, kills: int, seed: int) -> dict:
    runs = tmp_path / "runs"
    config = tmp_path / "killed.yaml"
    # No reference, and a small render that saves a checkpoint after every iteration: a whole run
    # takes about 3 s on 2 cores, a third of it rendering.
    config.write_text(
        block_config(
            runs,
            name="killed",
            seed=3,
            reference={"steady": False, "transient": False},
            render={
                "iterations": 24,
                "snapshot_every": 4,
                "light_paths_per_iteration": 6000,
                "checkpoint_every_iterations": 1,
            },
        )
    )
    run = runs / "killed"
    t0 = time.perf_counter()
    first = subprocess.run(
        pipeline_command(config),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(PROJECT_ROOT)},
    )
    full_run_s = time.perf_counter() - t0
    assert first.returncode == 0, first.stderr
    uninterrupted = {name: sha256(run / "render" / name) for name in ("frames.npy", "steady.npy")}

    seen = kill_and_check(config, run, kills, random.Random(seed), full_run_s)

    final = subprocess.run(
        pipeline_command(config, "--resume"), cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert final.returncode == 0, final.stderr
    assert assert_nothing_half_written(run) == sorted(STAGES)
    assert not list(run.glob(".*staging-*")) and not (run / ".render.checkpoint").exists()
    # Whether the render was resumed from a killed run's checkpoint or not, its bits are the same.
    assert {name: sha256(run / "render" / name) for name in uninterrupted} == uninterrupted
    return {"kills": kills, "full_run_s": round(full_run_s, 2), "stages_in_flight_at_kill": seen}


@pytest.mark.slow
def test_sigkill_at_24_random_moments_never_leaves_half_written_output(tmp_path):
    report = run_kill_test(tmp_path, kills=24, seed=20261201)
    print(report)
    assert sum(n for stage, n in report["stages_in_flight_at_kill"].items() if stage != "(none)") >= 8


def test_sigkill_at_6_random_moments_never_leaves_half_written_output(tmp_path):
    report = run_kill_test(tmp_path, kills=6, seed=7)
    print(report)

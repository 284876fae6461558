"""Resuming interrupted renders: the runner's checkpoint folder outlives the staging swap only under
--resume, and `pipeline run --resume` after Ctrl-C continues the render to the bits of an
uninterrupted one, or refuses a checkpoint of other settings with the setting that changed."""

from __future__ import annotations

import hashlib
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from block_scene import block_config

from pipeline.config import load_config
from pipeline.runner import Stage, checkpoint_dir, run_stages


@pytest.fixture
def config_file(tmp_path):
    path = tmp_path / "toy.yaml"
    path.write_text(f"seed: 1\nthreads: 1\nruns_dir: {tmp_path / 'runs'}\n")
    return path


def test_checkpoint_folder_is_kept_only_for_resume_and_removed_once_published(config_file, tmp_path):
    seen: list[bool] = []

    def resumable(ctx):
        progress = ctx.checkpoint_dir / "progress.txt"
        seen.append(progress.exists())
        progress.parent.mkdir(parents=True, exist_ok=True)
        progress.write_text("half\n")
        if ctx.config.threads == 1:
            raise KeyboardInterrupt  # stands for Ctrl-C: the stage stops and keeps its progress
        (ctx.out_dir / "done.txt").write_text("done\n")

    stages = [Stage("work", resumable, ("seed",))]
    folder = checkpoint_dir(tmp_path / "runs" / "toy", "work")
    with pytest.raises(KeyboardInterrupt):
        run_stages(load_config(config_file), stages, quiet=True)
    assert (folder / "progress.txt").exists() and seen == [False]
    # Without --resume the stale progress is removed before the stage starts.
    with pytest.raises(KeyboardInterrupt):
        run_stages(load_config(config_file), stages, quiet=True)
    assert seen == [False, False]
    # With --resume the stage finds it; publishing the finished output removes it.
    run_stages(load_config(config_file, ["threads=2"]), stages, quiet=True, resume=True)
    assert seen == [False, False, True] and not folder.exists()
    assert (tmp_path / "runs" / "toy" / "work" / "done.txt").exists()


def cli(config: Path, *args: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "pipeline",
            "run",
            str(config),
            "--quiet",
            "--stage",
            "scene",
            "--stage",
            "render",
            *args,
        ],
        cwd=config.parent,
        capture_output=True,
        text=True,
        timeout=300,
        **kwargs,
    )


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


ITERATIONS = 400


def test_resume_after_ctrl_c_gives_the_bits_of_an_uninterrupted_render(tmp_path):
    config = tmp_path / "resumed.yaml"
    config.write_text(
        block_config(
            tmp_path / "runs",
            name="resumed",
            seed=5,
            g=0.3,
            width=20,
            height=14,
            bins=10,
            reference={"steady": False, "transient": False},
            render={
                # The SIGINT must land while the render runs, between its first checkpoint (5) and its
                # end: the 400 iterations take about 0.8 s, polled every 10 ms.
                "iterations": ITERATIONS,
                "snapshot_every": 10,
                "light_paths_per_iteration": 1000,
                "checkpoint_every_iterations": 5,
                "frame_mode": "gate",
            },
        )
    )
    run = tmp_path / "runs" / "resumed"
    checkpoint = run / ".render.checkpoint" / "checkpoint.npz"
    process = subprocess.Popen(
        [sys.executable, "-m", "pipeline", "run", str(config), "--quiet", "--stage", "scene", "--stage", "render"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # A shell that starts `make test` in the background (`make test &`) hands its children SIGINT
        # ignored, and Python then installs no KeyboardInterrupt handler: the child would render to the end
        # and exit 0 (seen in fresh-clone runs started that way). Ctrl-C at a terminal is what is tested.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    start = time.monotonic()
    while not checkpoint.exists() and process.poll() is None and time.monotonic() < start + 120:
        time.sleep(0.01)
    seen = f"checkpoint seen: {checkpoint.exists()} after {time.monotonic() - start:.2f} s"
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, f"{seen}\n{stdout}\n{stderr}"
    assert "continue with `pipeline run --resume`" in stdout + stderr  # log lines go through tqdm.write
    assert checkpoint.exists() and not (run / "render").exists()

    # Another setting: the checkpoint is refused, naming it; nothing is rendered.
    refused = cli(config, "--resume", "--set", "render.initial_beam_radius.value=0.04")
    assert refused.returncode == 1
    assert "initial_beam_radius 0.03 -> 0.04" in refused.stderr and "run without --resume" in refused.stderr
    assert checkpoint.exists()

    resumed = cli(config, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert not checkpoint.parent.exists()
    bits = {name: digest(run / "render" / name) for name in ("frames.npy", "steady.npy")}
    stats = json.loads((run / "render" / "stats.json").read_text())
    assert stats["iterations"] == ITERATIONS

    # The same render without interruption, into another runs folder: byte-equal frames and image.
    fresh = cli(config, "--set", f"runs_dir={tmp_path / 'fresh'}")
    assert fresh.returncode == 0, fresh.stderr
    fresh_run = tmp_path / "fresh" / "resumed" / "render"
    assert {name: digest(fresh_run / name) for name in bits} == bits

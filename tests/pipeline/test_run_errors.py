"""What a run says when it cannot finish: a film too large for the run folder's disk is refused before
anything renders (pipeline/space.py), and a failure inside a stage is one line that names the stage
and the path, with the traceback in runs/<name>/run.log (and on the terminal with --debug)."""

from __future__ import annotations

import errno
import logging
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from block_scene import block_config
from typer.testing import CliRunner

import pipeline.stages
from pipeline import cli, space
from pipeline.config import load_config
from pipeline.manifest import file_sha256
from pipeline.runner import RUN_LOG, Stage, run_stages
from pipeline.space import NotEnoughSpace
from pipeline.stages import STAGES, render_writes

MIB = 2**20


def big_film_config(tmp_path: Path, runs: Path) -> Path:
    """The issue's film: 400 x 300 pixels, 96 bins, 132 MiB of float32 frames."""
    config = tmp_path / "big.yaml"
    config.write_text(
        block_config(
            runs,
            name="big",
            seed=1,
            width=400,
            height=300,
            bins=96,
            reference={"steady": False, "transient": False},
            render={"iterations": 4, "snapshot_every": 4, "light_paths_per_iteration": 2000},
        )
    )
    return config


def test_estimate_counts_the_film_the_render_writes(tmp_path):
    cfg = load_config(big_film_config(tmp_path, tmp_path / "runs"))
    film = 96 * 300 * 400 * 3 * 4
    assert film == 138_240_000  # numpy's figure in the issue's 'Not enough free space to write ... bytes'
    # frames.npy, steady.npy and .exr, one snapshot
    assert render_writes(cfg) == film + 3 * 300 * 400 * 3 * 4
    steady = load_config(big_film_config(tmp_path, tmp_path / "runs"), ["render.frame_mode=steady"])
    assert render_writes(steady) == 3 * 300 * 400 * 3 * 4


def test_a_film_too_large_for_the_disk_is_refused_before_any_stage(tmp_path, monkeypatch):
    cfg = load_config(big_film_config(tmp_path, tmp_path / "runs"))
    monkeypatch.setattr(space, "free_bytes", lambda folder: 40 * MIB)  # the issue's 40 MiB file system
    with pytest.raises(NotEnoughSpace) as refused:
        run_stages(cfg, STAGES, quiet=True)
    message = str(refused.value)
    assert f"write about {render_writes(cfg) / MIB:.1f} MiB (render " in message and "40.0 MiB free" in message
    assert "scene.film.temporal_bins = 96" in message and "runs_dir" in message
    run = tmp_path / "runs" / "big"
    assert sorted(p.name for p in run.iterdir()) == [".lock", RUN_LOG]  # no stage started, not even the scene


def test_space_is_checked_again_before_each_stage(tmp_path, monkeypatch):
    """Enough room when the run starts, too little once the first stage ran (another process filled the
    disk): the second stage refuses, and the first stage's output is kept."""
    config = tmp_path / "toy.yaml"
    config.write_text(f"seed: 1\nthreads: 1\nruns_dir: {tmp_path / 'runs'}\n")
    cfg = load_config(config)
    ran: list[str] = []

    def stage(name):
        def func(ctx):
            ran.append(name)
            (ctx.out_dir / f"{name}.txt").write_text(name)

        return func

    stages = [
        Stage("small", stage("small"), ("seed",), writes=lambda c: MIB),
        Stage("large", stage("large"), ("seed",), upstream=("small",), writes=lambda c: 30 * MIB),
    ]
    free = iter([64 * MIB, 64 * MIB, 16 * MIB])  # the whole run; before "small"; before "large"
    monkeypatch.setattr(space, "free_bytes", lambda folder: next(free))
    with pytest.raises(NotEnoughSpace, match=r"write about 30\.0 MiB \(large 30\.0 MiB\).* 16\.0 MiB free, so large"):
        run_stages(cfg, stages, quiet=True)
    assert ran == ["small"]
    assert (tmp_path / "runs" / "toy" / "small" / "manifest.json").is_file()
    assert not (tmp_path / "runs" / "toy" / "large").exists()


def unshare_command() -> list[str] | None:
    """A private mount namespace (as root, or as a mapped root where user namespaces are allowed) in which
    a tmpfs can be mounted and vanishes with the test; None where neither works."""
    if shutil.which("unshare") is None or shutil.which("mount") is None:
        return None
    command = ["unshare", "--mount"] + ([] if os.geteuid() == 0 else ["--map-root-user"])
    probe = subprocess.run(
        [*command, "sh", "-c", 'mount -t tmpfs -o size=1m tmpfs "$1"', "sh", "/mnt"],
        capture_output=True,
        timeout=30,
    )
    return command if probe.returncode == 0 else None


def test_on_a_40_mib_tmpfs_the_issue_film_is_refused_before_rendering(tmp_path):
    command = unshare_command()
    if command is None:
        pytest.skip("cannot mount a tmpfs here (no unshare, or no mount namespaces); the stubbed test covers it")
    small = tmp_path / "small"
    small.mkdir()
    config = big_film_config(tmp_path, small / "runs")
    script = 'mount -t tmpfs -o size=40m tmpfs "$1" && "$2" -m pipeline run "$3" --quiet; code=$?; ls -A "$1/runs/big"; exit $code'
    result = subprocess.run(
        [*command, "sh", "-c", script, "sh", str(small), sys.executable, str(config)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    print(result.stderr)
    assert result.returncode == 4, result.stderr
    assert "136.0 MiB" in result.stderr and "40.0 MiB free" in result.stderr  # both figures
    assert result.stdout.split() == [".lock", RUN_LOG]  # nothing rendered, no stage folder


def first_stage(ctx):
    (ctx.out_dir / "first.txt").write_text("kept")


def second_stage(ctx):
    np.save(ctx.out_dir / "frames.npy", np.ones(1000, np.float32))


def failing_second_stage(error: Callable[[Path], OSError]) -> Callable:
    """The second stage writes part of its film, then raises ``error(its output folder)``."""

    def second(ctx):
        np.save(ctx.out_dir / "half.npy", np.zeros(1000, np.float32))
        raise error(ctx.out_dir)

    return second


def toy_stages(second: Callable) -> list[Stage]:
    return [Stage("first", first_stage, ("seed",)), Stage("second", second, ("seed", "threads"), upstream=("first",))]


@pytest.fixture
def toy_run(tmp_path, monkeypatch):
    config = tmp_path / "toy.yaml"
    config.write_text(f"seed: 1\nthreads: 1\nruns_dir: {tmp_path / 'runs'}\n")
    monkeypatch.chdir(tmp_path)
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield config, tmp_path / "runs" / "toy"
    root.handlers[:] = handlers  # `pipeline run` set up its terminal logging in this process
    root.setLevel(level)


def run_cli(monkeypatch, stages: list[Stage], *args: str):
    monkeypatch.setattr(pipeline.stages, "STAGES", stages)  # `pipeline run` reads the stages from here
    return CliRunner().invoke(cli.app, ["run", *args])


@pytest.mark.parametrize(
    ("error", "what", "where"),
    [
        (
            lambda out: OSError(errno.ENOSPC, "No space left on device", str(out / "frames.npy")),
            "No space left on device",
            "at {final}/frames.npy",  # the file as it would have been published, not the removed staging copy
        ),
        (
            lambda out: OSError(errno.ENOSPC, "No space left on device", str(out / ".transient.tmp-42-0123abcd.mp4")),
            "No space left on device",
            "at {final}/transient.mp4",  # the file atomic_path was writing, not its temporary name
        ),
        (
            lambda out: OSError("Not enough free space to write 138240000 bytes"),  # numpy's, without a path
            "Not enough free space to write 138240000 bytes",
            "writing {final}",
        ),
    ],
)
def test_an_oserror_in_a_stage_is_one_line_naming_the_stage_and_path(toy_run, monkeypatch, error, what, where):
    config, run = toy_run
    assert run_cli(monkeypatch, toy_stages(second_stage), str(config), "--quiet").exit_code == 0
    final = run / "second"
    before = {p.name: file_sha256(p) for p in final.iterdir()}

    result = run_cli(monkeypatch, toy_stages(failing_second_stage(error)), str(config), "--quiet", "--set", "threads=2")
    assert result.exit_code == 1
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"error: stage second failed: {what}, {where.format(final=final)} ")
    assert f"{final} is as before the run" in lines[0] and str(run / RUN_LOG) in lines[0]
    assert "Traceback" not in result.stderr
    # The stage folder is as before the run: same files, same bytes, no staging folder left.
    assert {p.name: file_sha256(p) for p in final.iterdir()} == before
    assert not list(run.glob(".*staging-*"))
    log = (run / RUN_LOG).read_text()
    assert "Traceback (most recent call last)" in log and "in second" in log and what in log

    debug = run_cli(
        monkeypatch, toy_stages(failing_second_stage(error)), str(config), "--quiet", "--set", "threads=2", "--debug"
    )
    assert debug.exit_code == 1
    assert "Traceback (most recent call last)" in debug.stderr and "in second" in debug.stderr
    assert debug.stderr.splitlines()[-1] == lines[0]

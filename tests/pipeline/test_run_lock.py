"""One writer per run folder (pipeline/lock.py): two `pipeline run` of one config started together, a
run killed while it holds the lock, and the folders that must not wait for each other (sweep points,
shard jobs). Every holder here is a real process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from block_scene import block_config

from pipeline.lock import LOCK_NAME, RunFolderBusy, hold_run_folder, read_holder

RUN_STAGES = ("scene", "render", "composite", "compare")  # the block scene has no geometry, no reference


def pipeline_run(config: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "pipeline", "run", str(config), "--quiet", *extra]


def write_config(tmp_path: Path, name: str, iterations: int) -> Path:
    config = tmp_path / f"{name}.yaml"
    config.write_text(
        block_config(
            tmp_path / "runs",
            name=name,
            seed=5,
            reference={"steady": False, "transient": False},
            render={"iterations": iterations, "snapshot_every": 4, "light_paths_per_iteration": 6000},
        )
    )
    return config


def wait_for_holder(folder: Path, process: subprocess.Popen, timeout_s: float = 60.0) -> dict:
    """The lock record once ``process`` holds ``folder``'s lock; fails if it ends or never takes it."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        record = read_holder(folder / LOCK_NAME)
        if record and record.get("pid") == process.pid:
            return record
        assert process.poll() is None, f"the first run ended (exit {process.returncode}) before it took the lock"
        time.sleep(0.02)
    raise AssertionError(f"pid {process.pid} did not take the lock of {folder} within {timeout_s} s")


def statuses(stdout: str) -> dict[str, str]:
    """Each stage's status from `pipeline run`'s closing table."""
    rows = [line.split() for line in stdout.splitlines() if line.startswith("  ")]
    return {row[0]: row[1] for row in rows if len(row) >= 2 and row[0] in RUN_STAGES}


def test_a_second_run_waits_or_refuses_and_a_third_reruns_nothing(tmp_path):
    # 96 iterations: the first run holds the folder for several seconds, long enough for two more to start.
    config = write_config(tmp_path, "twice", iterations=96)
    folder = tmp_path / "runs" / "twice"
    first = subprocess.Popen(
        pipeline_run(config), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    holder = wait_for_holder(folder, first)
    assert holder["command"].endswith(f"-m pipeline run {config} --quiet") and holder["host"]
    waiting = subprocess.Popen(
        pipeline_run(config), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    refused = subprocess.run(
        pipeline_run(config, "--no-wait"), cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert first.poll() is None, "the first run finished before --no-wait was tried; the test proves nothing"
    assert refused.returncode == 3, refused.stderr
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and f"is in use by pid {first.pid} on " in lines[0] and "--no-wait" in lines[0], lines

    out, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    assert set(statuses(out).values()) == {"ran"}
    out, err = waiting.communicate(timeout=300)
    assert waiting.returncode == 0, err
    assert f"is in use by pid {first.pid} on " in out and "waiting for it" in out  # logged, as progress is
    assert statuses(out) == dict.fromkeys(RUN_STAGES, "skipped"), out

    third = subprocess.run(pipeline_run(config, "--no-wait"), cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert third.returncode == 0, third.stderr
    assert statuses(third.stdout) == dict.fromkeys(RUN_STAGES, "skipped"), third.stdout
    assert not list(folder.glob(".*staging-*"))


def test_a_run_killed_while_holding_the_lock_does_not_block_the_next(tmp_path):
    config = write_config(tmp_path, "killed", iterations=24)
    folder = tmp_path / "runs" / "killed"
    first = subprocess.Popen(pipeline_run(config), cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wait_for_holder(folder, first)
    os.kill(first.pid, signal.SIGKILL)
    assert first.wait(timeout=30) == -signal.SIGKILL
    assert read_holder(folder / LOCK_NAME)["pid"] == first.pid  # its record stays; its lock went with it
    t0 = time.perf_counter()
    after = subprocess.run(pipeline_run(config, "--no-wait"), cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert after.returncode == 0, after.stderr
    assert "in use" not in after.stderr
    assert statuses(after.stdout)["render"] == "ran"
    print(f"the run after the killed one took {time.perf_counter() - t0:.1f} s")


HOLDER = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from pipeline.lock import hold_run_folder
    with hold_run_folder(Path(sys.argv[1]), shared=sys.argv[2] == "shared"):
        print("held", flush=True)
        sys.stdin.read()  # until the test closes our stdin
    """
)


def hold_in_another_process(folder: Path, mode: str) -> subprocess.Popen:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder), mode], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline() == "held\n"
    return holder


def release(holder: subprocess.Popen) -> None:
    assert holder.stdin is not None
    holder.stdin.close()
    assert holder.wait(timeout=30) == 0


def test_a_waiting_run_names_the_holder_and_goes_on_when_it_ends(tmp_path):
    folder = tmp_path / "runs" / "one"
    holder = hold_in_another_process(folder, "exclusive")
    messages: list[str] = []

    def on_wait(message: str) -> None:
        messages.append(message)
        release(holder)

    with hold_run_folder(folder, on_wait=on_wait):
        assert read_holder(folder / LOCK_NAME)["pid"] == os.getpid()
    assert len(messages) == 1 and f"in use by pid {holder.pid} on " in messages[0]


def test_sweep_points_and_shard_jobs_do_not_wait_for_each_other(tmp_path):
    runs = tmp_path / "runs"
    point = hold_in_another_process(runs / "sweep-set1", "exclusive")
    shard = hold_in_another_process(runs / "sharded", "shared")
    try:
        with hold_run_folder(runs / "sweep-set6", wait=False):  # another sweep point: its own folder, its own lock
            pass
        with hold_run_folder(runs / "sharded", shared=True, wait=False):  # a second shard job beside the first
            pass
        with pytest.raises(RunFolderBusy, match="shard jobs"), hold_run_folder(runs / "sharded", wait=False):
            pass  # but a `pipeline run` of the sharded folder waits for its shards
        with (
            pytest.raises(RunFolderBusy, match=f"pid {point.pid} "),
            hold_run_folder(runs / "sweep-set1", shared=True, wait=False),
        ):
            pass  # and a shard job waits for a run of its folder
    finally:
        release(point)
        release(shard)

"""Sweeps and sharded renders through a real SLURM cluster: sbatch, slurmctld, slurmd and accounting.

`make cluster-test` starts a one-node cluster on localhost (tests/pipeline/cluster/slurm_cluster.sh) and runs
these tests; without a cluster that answers `sinfo` they are skipped. Every run goes through a copy of
profiles/slurm/config.yaml sized for the node (one CPU and 1000 MB a job) that polls job states
every few seconds instead of every 40 s; everything else is the shipped profile (retries, keep-going).
"""

from __future__ import annotations

import csv
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.slurm import GRACE_ENV, cluster_nodes
from pipeline.sweep import load_sweep

PROJECT = Path(__file__).resolve().parents[3]
CLUSTER_SCRIPT = PROJECT / "tests" / "pipeline" / "cluster" / "slurm_cluster.sh"
sys.path.insert(0, str(PROJECT / "tests" / "pipeline"))
from block_scene import block_config  # noqa: E402
from test_sweep import TINY_BASE  # noqa: E402


def _cluster_answers() -> bool:
    if shutil.which("sinfo") is None:
        return False
    try:
        return subprocess.run(["sinfo", "--noheader"], capture_output=True, timeout=15).returncode == 0
    except subprocess.TimeoutExpired:
        return False


pytestmark = [
    pytest.mark.cluster,
    pytest.mark.skipif(not _cluster_answers(), reason="no SLURM cluster answers sinfo: run `make cluster-test`"),
]

# The timing columns of a sweep summary differ between any two runs; every other cell must not.
TIMING_SUFFIX = "_s"
# The shard tests' tolerance (tests/pipeline/test_shards.py): float64 sums merged in another order.
SHARD_RTOL = 1e-6


def pipeline(*args, cwd: Path, env: dict | None = None, timeout: int = 400) -> subprocess.CompletedProcess[str]:
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )
    print(f"$ pipeline {' '.join(map(str, args))}  -> exit {result.returncode}")
    return result


def tail(result: subprocess.CompletedProcess[str]) -> str:
    return (result.stdout + result.stderr)[-4000:]


def node():
    return max(cluster_nodes(), key=lambda n: n.cpus)


def sized_profile(folder: Path, **changes) -> Path:
    """profiles/slurm/config.yaml with one CPU and 1000 MB a job, fast status checks, and ``changes``."""
    profile = yaml.safe_load((PROJECT / "profiles" / "slurm" / "config.yaml").read_text())
    profile["set-threads"] = {"point": 1, "shard": 1, "merge": 1}
    profile["set-resources"] = {rule: {"mem_mb": 1000, "runtime": 10} for rule in ("point", "shard", "merge")}
    profile["slurm-init-seconds-before-status-checks"] = 2
    profile["latency-wait"] = 5
    profile.update({key.replace("_", "-"): value for key, value in changes.items()})
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "config.yaml").write_text(yaml.safe_dump(profile, sort_keys=False))
    return folder


def workflow_jobs(folder: Path) -> list[dict[str, str]]:
    """Every SLURM job (sacct) that ran in a workflow folder: id, comment (rule and wildcards), state."""
    result = subprocess.run(
        ["sacct", "--allocations", "--noheader", "--parsable2", "--format=JobIDRaw,WorkDir,Comment,State"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    rows = [line.split("|") for line in result.stdout.splitlines()]
    return [{"id": r[0], "comment": r[2], "state": r[3]} for r in rows if len(r) >= 4 and Path(r[1]) == folder]


def queued(folder: Path, state: str) -> list[str]:
    result = subprocess.run(
        ["squeue", "--noheader", f"--states={state}", "--format=%i|%Z"], capture_output=True, text=True, timeout=30
    )
    return [line.split("|")[0] for line in result.stdout.splitlines() if Path(line.split("|")[1]) == folder]


def wait_until(condition, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.5)
    raise AssertionError(f"{what} did not happen within {timeout} s")


def summary_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def write_sweep(path: Path, sweep: dict) -> Path:
    path.write_text(yaml.safe_dump(sweep, sort_keys=False))
    return path


def reduced_default_sweep(folder: Path) -> Path:
    """configs/sweeps/default.yaml as shipped (base, points, seeds), at a size that runs in seconds."""
    sweep = yaml.safe_load((PROJECT / "configs" / "sweeps" / "default.yaml").read_text())
    sweep["base"] = str(PROJECT / "configs" / "sweeps" / sweep["base"])
    sweep["set"] = {
        "runs_dir": str(folder / "runs"),
        "geometry.grid_cells": 24,
        "geometry.days": 10,
        "scene.camera.width": 24,
        "scene.camera.height": 16,
        "scene.film.temporal_bins": 8,
        "render.iterations": 4,
        "render.light_paths_per_iteration": 2000,
        "reference.steady": False,  # Mitsuba's JIT alone takes half a minute a point on 2 cores
        "reference.transient": False,
    }
    folder.mkdir(parents=True, exist_ok=True)
    return write_sweep(folder / "default.yaml", sweep)


def box_sweep(folder: Path, points: list[str], paths_per_iteration: int) -> Path:
    """The sweep tests' box of snow, with a render of ``paths_per_iteration`` light paths x 8 per point."""
    (folder / "base.yaml").parent.mkdir(parents=True, exist_ok=True)
    (folder / "base.yaml").write_text(TINY_BASE)
    sweep = {
        "base": "base.yaml",
        "set": {
            "runs_dir": str(folder / "runs"),
            "render.iterations": 8,
            "render.light_paths_per_iteration": paths_per_iteration,
        },
        "points": [{"name": name, "set": {"seed": seed}} for seed, name in enumerate(points, 1)],
    }
    return write_sweep(folder / "box.yaml", sweep)


# ---------------------------------------------------------------- end to end


def test_default_sweep_through_slurm_equals_the_local_run(tmp_path):
    local = reduced_default_sweep(tmp_path / "local")
    remote = reduced_default_sweep(tmp_path / "slurm")
    ran = pipeline("sweep", local, "--cores", "2", cwd=tmp_path)
    assert ran.returncode == 0, tail(ran)
    ran = pipeline("sweep", remote, "--profile", sized_profile(tmp_path / "profile"), cwd=tmp_path)
    assert ran.returncode == 0, tail(ran)

    folder = tmp_path / "slurm" / "runs" / "sweeps" / "default"
    jobs = workflow_jobs(folder)
    assert sorted(job["comment"] for job in jobs) == sorted(
        f"rule_point_wildcards_{p.name}" for p in load_sweep(remote).points
    )
    assert {job["state"] for job in jobs} == {"COMPLETED"}
    expected = summary_rows(tmp_path / "local" / "runs" / "sweeps" / "default" / "summary.csv")
    got = summary_rows(folder / "summary.csv")
    assert len(got) == len(expected) == 3 and list(got[0]) == list(expected[0])
    compared = [key for key in expected[0] if not key.endswith(TIMING_SUFFIX)]
    numbers = [key for key in compared if expected[0][key].replace(".", "", 1).replace("-", "", 1).isdigit()]
    assert len(numbers) >= 8, compared
    for want, have in zip(expected, got, strict=True):
        assert {k: have[k] for k in compared} == {k: want[k] for k in compared}
    # The summary's render figures are timings; the frames behind them must match bit for bit.
    for point in load_sweep(remote).points:
        frames = [
            np.load(tmp_path / side / "runs" / f"default-{point.name}" / "render" / "frames.npy")
            for side in ("local", "slurm")
        ]
        assert np.count_nonzero(frames[0]) > 0 and np.array_equal(frames[0], frames[1]), point.name
    print(f"summary: {len(expected)} points x {len(compared)} columns equal ({len(numbers)} numeric); frames equal")


def test_two_shards_through_slurm_merge_to_one_local_pass(tmp_path):
    render = {"iterations": 6, "light_paths_per_iteration": 400, "snapshot_every": 0, "frame_mode": "gate"}
    reference = {"steady": False, "transient": False}
    for name in ("plain", "sharded"):
        text = block_config(tmp_path / "runs", name=name, seed=2, render=render, reference=reference)
        (tmp_path / f"{name}.yaml").write_text(text)
    ran = pipeline("run", "plain.yaml", "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, tail(ran)
    profile = sized_profile(tmp_path / "profile")
    ran = pipeline("run", "sharded.yaml", "--quiet", "--shards", "2", "--profile", profile, cwd=tmp_path)
    assert ran.returncode == 0, tail(ran)

    jobs = workflow_jobs(tmp_path / "runs" / "sharded" / ".workflow")
    assert sorted(job["comment"] for job in jobs) == [
        "rule_merge",
        "rule_shard_wildcards_0",
        "rule_shard_wildcards_1",
    ], jobs
    plain = np.load(tmp_path / "runs" / "plain" / "render" / "frames.npy")
    merged = np.load(tmp_path / "runs" / "sharded" / "render" / "frames.npy")
    assert np.count_nonzero(plain) > 0
    np.testing.assert_allclose(merged, plain, rtol=SHARD_RTOL, atol=0)
    lit = plain != 0
    print(f"shards: max relative difference {np.max(np.abs(merged[lit] - plain[lit]) / np.abs(plain[lit])):.3g}")


def test_first_two_points_of_the_lidar_bias_sweep(tmp_path):
    shipped = load_sweep(PROJECT / "configs" / "sweeps" / "lidar_biases.yaml")
    sweep = {
        "name": shipped.name,
        "base": str(shipped.base),
        "threads": 1,
        "set": [*shipped.common, f"runs_dir={tmp_path / 'runs'}", "lidar.pixels=24", "lidar.iterations=4"],
        "points": [{"name": p.name, "set": list(p.overrides)} for p in shipped.points[:2]],
    }
    sweep_file = write_sweep(tmp_path / "lidar_biases.yaml", sweep)
    ran = pipeline("sweep", sweep_file, "--profile", sized_profile(tmp_path / "profile"), cwd=tmp_path)
    assert ran.returncode == 0, tail(ran)
    folder = tmp_path / "runs" / "sweeps" / shipped.name
    assert {job["state"] for job in workflow_jobs(folder)} == {"COMPLETED"}
    rows = summary_rows(folder / "summary.csv")
    assert [row["run"] for row in rows] == [p.name for p in shipped.points[:2]]
    biases = summary_rows(folder / "biases.csv")
    numbers = [float(row[key]) for row in biases for key in row if key.startswith("bias_")]
    assert len(numbers) >= 2 * 3 * 5 and all(math.isfinite(v) for v in numbers), biases
    print(f"lidar: {len(rows)} points, {len(numbers)} finite biases")


# ---------------------------------------------------------------- faults


def test_a_killed_point_is_retried_and_keeps_its_finished_stages(tmp_path):
    sweep_file = box_sweep(tmp_path, ["long"], paths_per_iteration=400_000)
    folder = tmp_path / "runs" / "sweeps" / "box"
    scene_done = tmp_path / "runs" / "box-long" / "scene" / "manifest.json"
    command = [
        sys.executable,
        "-m",
        "pipeline",
        "sweep",
        str(sweep_file),
        "--profile",
        str(sized_profile(tmp_path / "p")),
    ]
    with subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as run:
        job = wait_until(lambda: scene_done.is_file() and queued(folder, "RUNNING"), 120, "the point's scene stage")[0]
        subprocess.run(["scancel", job], check=True)
        output, _ = run.communicate(timeout=300)
    print(f"scancel {job} after the scene stage; snakemake said:")
    print("\n".join(line for line in output.splitlines() if "SLURM" in line or "restart" in line.lower()))
    assert run.returncode == 0, output[-4000:]
    assert "CANCELLED" in output and "Trying to restart" in output
    states = sorted(job["state"] for job in workflow_jobs(folder))
    assert states[0].startswith("CANCELLED") and states[1:] == ["COMPLETED"], states
    retried = (folder / "logs" / "long.log").read_text()
    print("the retry's point log:\n" + retried)
    assert "scene      skipped" in retried and "render     ran" in retried
    assert (folder / "summary.csv").is_file()


@pytest.mark.parametrize("resource", ["cpus", "memory"])
def test_a_job_larger_than_any_node_is_refused_before_submitting(tmp_path, resource):
    biggest = node()
    sweep_file = box_sweep(tmp_path, ["a"], paths_per_iteration=1000)
    if resource == "cpus":
        profile = sized_profile(tmp_path / "p", set_threads={"point": biggest.cpus + 1})
        key = "set-threads.point"
    else:
        resources = {"point": {"mem_mb": biggest.memory_mb + 1000, "runtime": 10}}
        profile = sized_profile(tmp_path / "p", set_resources=resources)
        key = "set-resources.point.mem_mb"
    started = time.monotonic()
    ran = pipeline("sweep", sweep_file, "--profile", profile, cwd=tmp_path, timeout=60)
    print(ran.stderr)
    assert ran.returncode == 2 and time.monotonic() - started < 30
    lines = ran.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {profile / 'config.yaml'}: {key} = ")
    assert f"the largest node ({biggest.name})" in lines[0] and f"lower {key} to" in lines[0]
    assert workflow_jobs(tmp_path / "runs" / "sweeps" / "box") == []


def test_without_accounting_a_sacct_profile_is_refused_and_the_shipped_one_runs(tmp_path):
    sweep_file = box_sweep(tmp_path, ["a", "b"], paths_per_iteration=1000)
    subprocess.run([CLUSTER_SCRIPT, "dbd-stop"], check=True)
    try:
        started = time.monotonic()
        profile = sized_profile(tmp_path / "sacct", slurm_status_command="sacct")
        refused = pipeline("sweep", sweep_file, "--profile", profile, cwd=tmp_path, timeout=60)
        print(refused.stderr)
        assert refused.returncode == 2 and time.monotonic() - started < 30
        lines = refused.stderr.strip().splitlines()
        assert len(lines) == 1 and "SLURM accounting is unavailable (sacct: " in lines[0]
        assert "set slurm-status-command: squeue" in lines[0]
        assert not (tmp_path / "runs" / "box-a").exists()
        # The shipped profile follows its jobs with squeue: it says so in one line and finishes.
        ran = pipeline("sweep", sweep_file, "--profile", sized_profile(tmp_path / "squeue"), cwd=tmp_path, timeout=300)
        assert ran.returncode == 0, tail(ran)
        notice = [line for line in (ran.stdout + ran.stderr).splitlines() if "accounting is unavailable" in line]
        print("\n".join(notice))
        assert len(notice) == 1 and "jobs are followed with squeue (slurm-status-command: squeue)" in notice[0]
        assert len(summary_rows(tmp_path / "runs" / "sweeps" / "box" / "summary.csv")) == 2
    finally:
        subprocess.run([CLUSTER_SCRIPT, "dbd-start"], check=True)


def test_a_drained_node_leaves_points_that_a_rerun_after_resume_finishes(tmp_path):
    points = ["p1", "p2", "p3"]
    sweep_file = box_sweep(tmp_path, points, paths_per_iteration=100_000)
    folder = tmp_path / "runs" / "sweeps" / "box"
    profile = sized_profile(tmp_path / "p")
    command = [sys.executable, "-m", "pipeline", "sweep", str(sweep_file), "--profile", str(profile)]
    name = node().name
    env = {**os.environ, GRACE_ENV: "5"}
    try:
        with subprocess.Popen(
            command, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        ) as run:
            wait_until(lambda: len(queued(folder, "RUNNING")) == node().cpus, 120, "a job on every CPU")
            subprocess.run(["scontrol", "update", f"nodename={name}", "state=drain", "reason=test"], check=True)
            stdout, stderr = run.communicate(timeout=300)
        said = [line for line in (stdout + stderr).splitlines() if "cancelled" in line or "points not run" in line]
        print("\n".join(said))
        assert run.returncode != 0
        not_run = [p for p in points if not (tmp_path / "runs" / f"box-{p}" / "compare" / "manifest.json").is_file()]
        assert len(not_run) == len(points) - node().cpus, not_run
        assert f"points not run: {', '.join(not_run)}; a rerun runs only those" in stderr
        assert f"no node of partition 'debug' has taken jobs for 5 s ({name} dr" in stdout + stderr
    finally:
        subprocess.run(["scontrol", "update", f"nodename={name}", "state=resume"], check=True)
    done = {
        p: (tmp_path / "runs" / f"box-{p}" / "compare" / "manifest.json").read_text()
        for p in points
        if p not in not_run
    }
    rerun = pipeline("sweep", sweep_file, "--profile", profile, cwd=tmp_path)
    assert rerun.returncode == 0, tail(rerun)
    output = rerun.stdout + rerun.stderr
    assert all(f"wildcards: point={p}" in output for p in not_run)
    assert not any(f"wildcards: point={p}" in output for p in done)
    assert {p: (tmp_path / "runs" / f"box-{p}" / "compare" / "manifest.json").read_text() for p in done} == done

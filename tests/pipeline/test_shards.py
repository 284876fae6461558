"""`pipeline run CONFIG --shards K`: the SLURM workflow's dry run, and the refusals before any work."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[2]


def pipeline(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def test_slurm_dry_run_prints_the_shard_jobs_and_the_merge(tmp_path):
    config = PROJECT / "configs" / "assets" / "video.yaml"
    runs = tmp_path / "runs"
    result = pipeline(
        "run", str(config), "--shards", "8", "--profile", "slurm", "-n", "--set", f"runs_dir={runs}", cwd=tmp_path
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    assert "profiles/slurm" in output
    for index in range(8):
        assert f"wildcards: index={index}" in output, output[-3000:]
    assert "rule merge:" in output
    assert "rule prepare:" in output
    assert not (runs / "video" / "render").exists()


def test_shards_refuse_a_time_budget_naming_the_keys(tmp_path):
    config = PROJECT / "configs" / "assets" / "video_preview.yaml"
    result = pipeline(
        "run",
        str(config),
        "--shards",
        "4",
        "--set",
        "render.time_budget_s=60",
        "--set",
        f"runs_dir={tmp_path}",
        cwd=tmp_path,
    )
    assert result.returncode == 2
    assert "render.time_budget_s and --shards do not mix" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_shard_jobs_then_the_merge_run_equal_the_plain_run(tmp_path):
    """What the SLURM workflow does, by hand: the stages before the render, `pipeline shard` per shard (in
    any order), then `pipeline run --shards K`, which merges; its frames equal a plain run's."""
    import numpy as np
    from block_scene import block_config

    render = {"iterations": 6, "light_paths_per_iteration": 400, "snapshot_every": 0, "frame_mode": "gate"}
    reference = {"steady": False, "transient": False}
    for name in ("plain", "sharded"):
        text = block_config(tmp_path / "runs", name=name, seed=2, render=render, reference=reference)
        (tmp_path / f"{name}.yaml").write_text(text)
    assert (
        pipeline("run", "plain.yaml", "--quiet", "--stage", "scene", "--stage", "render", cwd=tmp_path).returncode == 0
    )
    assert pipeline("run", "sharded.yaml", "--quiet", "--stage", "scene", cwd=tmp_path).returncode == 0
    for index in (2, 0, 1):
        job = pipeline("shard", "sharded.yaml", "--quiet", "--index", str(index), "--shards", "3", cwd=tmp_path)
        assert job.returncode == 0, job.stderr[-2000:]
    shards = tmp_path / "runs" / "sharded" / ".render.shards"
    assert sorted(p.name for p in shards.iterdir()) == ["shard-0", "shard-1", "shard-2"]
    merge = pipeline("run", "sharded.yaml", "--quiet", "--stage", "render", "--shards", "3", cwd=tmp_path)
    assert merge.returncode == 0, merge.stderr[-2000:]
    assert not shards.exists()  # the published render supersedes its shards
    plain = np.load(tmp_path / "runs" / "plain" / "render" / "frames.npy")
    merged = np.load(tmp_path / "runs" / "sharded" / "render" / "frames.npy")
    assert np.count_nonzero(plain) > 0
    np.testing.assert_allclose(merged, plain, rtol=1e-6, atol=0)

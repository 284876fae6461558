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

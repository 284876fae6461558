"""The CLI end to end on a tiny real config: validate, run, skip when nothing changed, re-run on a change."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def cli(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


@pytest.fixture
def tiny_config(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(
        "extends: [presets/sites/tapado.yaml]\n"
        f"runs_dir: {tmp_path / 'runs'}\n"
        "geometry:\n  grid_cells: 64\n  days: 1\n  snapshots: 2\n  preview_size: 128\n"
        # The references of the default firn start their roulette at 20000 collisions (reference.rr_depth: auto),
        # minutes of path tracing that these tests of the stage runner do not need.
        "reference:\n  steady: false\n  transient: false\n"
    )
    return path


def test_validate_reports_key_path_value_and_rule(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("geometry:\n  days: -3\n  colour: blue\nthreads: lots\n")
    result = cli("validate", str(bad), cwd=tmp_path)
    assert result.returncode == 2
    assert "geometry.days: value -3 is not allowed" in result.stderr
    assert "geometry.colour: unknown key" in result.stderr
    assert "threads: value 'lots' is not allowed" in result.stderr


def test_validate_warns_when_the_season_cannot_ablate(tmp_path):
    """Rio Blanco's snow preset in the constant-loss mode (no meteorology) under the default sky loss: valid, but
    validate says the field will not grow and which keys to look at (geometry/DESIGN.md 7, Limits)."""
    config = tmp_path / "rio.yaml"
    config.write_text(
        "extends: [presets/sites/rio_blanco.yaml]\n"
        "geometry:\n  grid_cells: 128\n  domain_size: 4.0\n  meteorology: null\n"
    )
    result = cli("validate", str(config), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "warning: flat ground loses 0 mm over the 40-day season: geometry.sky_loss = 90" in result.stderr
    assert "valid" in result.stderr


def test_run_skips_a_finished_stage_and_reruns_on_a_change(tiny_config, tmp_path):
    first = cli("run", str(tiny_config), "--quiet", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    assert "geometry   ran" in first.stdout
    manifest_path = tmp_path / "runs" / "tiny" / "geometry" / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    assert {"penitentes.ply", "metrics.json", "preview.png"} <= set(manifest["outputs"])
    second = cli("run", str(tiny_config), "--quiet", cwd=tmp_path)
    assert second.returncode == 0 and "geometry   skipped" in second.stdout
    third = cli("run", str(tiny_config), "--quiet", "--set", "geometry.days=2", cwd=tmp_path)
    assert third.returncode == 0 and "geometry   ran" in third.stdout
    assert json.loads(manifest_path.read_text())["config_hash"] != manifest["config_hash"]

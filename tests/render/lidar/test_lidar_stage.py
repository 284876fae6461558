"""The lidar stage in the pipeline (render/lidar/LIDAR.md §7.4): which stages a lidar run runs, its config's
errors, and a shot at a bare plane and at flat snow through the runner, with the files and figures it
writes."""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from pipeline.config import ConfigError, load_config
from pipeline.runner import run_stages
from pipeline.stages import STAGES


def lidar_config(tmp_path, name: str, **lidar) -> object:
    settings = {"enabled": True, "footprint_diameter": 0.2, "pixels": 16, "iterations": 4, "tail_range": 0.1}
    settings.update(lidar)
    body = "\n".join(f"  {k}: {v}" for k, v in settings.items())
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"name: {name}\nruns_dir: {tmp_path / 'runs'}\nthreads: 2\nlidar:\n{body}\n")
    return load_config(path)


def test_a_lidar_run_runs_geometry_and_lidar_only(tmp_path):
    cfg = lidar_config(tmp_path, "shot", target="penitentes")
    enabled = [s.name for s in STAGES if s.enabled(cfg)]
    assert enabled == ["geometry", "lidar"]
    flat = lidar_config(tmp_path, "flat", target="flat_snow")
    assert [s.name for s in STAGES if s.enabled(flat)] == ["lidar"]


def test_a_range_bin_that_cannot_resolve_the_pulse_is_refused_by_name(tmp_path):
    with pytest.raises(ConfigError, match=r"lidar.range_bin .* use at most"):
        lidar_config(tmp_path, "coarse", range_bin=0.1)
    with pytest.raises(ConfigError, match="lidar.density"):
        lidar_config(tmp_path, "dense", density=950.0)


def test_a_bare_plane_reads_zero_bias_through_the_stage(tmp_path):
    """A Lambertian plane of albedo 0.5: apparent reflectance 0.5 in every channel (within 2 %: a diffuse
    surface is a surface-photon density estimate), and every estimator within a fifth of a range bin of the
    plane (the reference plane stands 0.1 m above it)."""
    cfg = lidar_config(tmp_path, "bare", target="bare", bare_albedo=0.5, iterations=32)
    results = run_stages(cfg, STAGES, quiet=True)
    assert {r.name: r.status for r in results}["lidar"] == "ran"
    out = tmp_path / "runs" / "bare" / "lidar"
    summary = json.loads((out / "summary.json").read_text())
    for channel in summary["channels"]:
        assert channel["apparent_reflectance"] == pytest.approx(0.5, rel=0.02)
        for estimator, by_reference in channel["bias_m"].items():
            assert abs(by_reference["flat_equivalent"]) < 0.2 * cfg.lidar.range_bin, estimator
    rows = list(csv.DictReader((out / "biases.csv").open()))
    assert len(rows) == 3 * 5 * 3  # channels x estimators x references
    data = np.load(out / "waveform.npz")
    assert data["impulse"].shape == data["pulsed"].shape == (len(data["range_m"]), 3)
    assert (out / "waveform.png").stat().st_size > 10_000


def test_flat_snow_reads_late_and_1064_nm_less_late(tmp_path):
    """Flat snow of 300 kg/m3 and 0.5 mm grains: every estimator places the surface below the plane (positive
    bias), the centroid more than the first return, and 1064 nm (ice absorbs 640x more) less than 532 nm; the
    apparent reflectance at 532 nm is close to 1 and at 1064 nm well below it."""
    cfg = lidar_config(
        tmp_path, "flat", target="flat_snow", density=300.0, optical_diameter=0.0005, tail_range=1.0, iterations=16
    )
    run_stages(cfg, STAGES, quiet=True)
    summary = json.loads((tmp_path / "runs" / "flat" / "lidar" / "summary.json").read_text())
    green, picard, infrared = summary["channels"]
    for channel in (green, picard):
        bias = {k: v["flat_equivalent"] for k, v in channel["bias_m"].items()}
        assert all(v > 0 for v in bias.values()), bias
        assert bias["centroid"] > bias["first_return"]
    assert infrared["bias_m"]["centroid"]["flat_equivalent"] < green["bias_m"]["centroid"]["flat_equivalent"]
    assert green["apparent_reflectance"] > 0.9
    assert infrared["apparent_reflectance"] < 0.8 * green["apparent_reflectance"]
    assert not math.isnan(green["estimates"]["gaussian_fit"])


@pytest.mark.skipif(importlib.util.find_spec("snakemake") is None, reason="snakemake not installed")
def test_a_lidar_sweep_summarises_its_biases(tmp_path):
    """A sweep of two shots through the workflow (`python -m pipeline sweep`): a bare plane and flat snow. Its
    summary is the bias table: a row per point (532 nm, flat-equivalent reference) where the plane reads zero
    within a fifth of a range bin and the snow reads late by every estimator, the full table (two points x 3
    channels x 5 estimators), the waveforms' figure and the report."""
    base = tmp_path / "base.yaml"
    base.write_text(
        f"runs_dir: {tmp_path / 'runs'}\nthreads: 2\nlidar:\n  enabled: true\n  footprint_diameter: 0.2\n"
        "  pixels: 16\n  iterations: 16\n  tail_range: 0.5\n  bare_albedo: 0.5\n"
    )
    (tmp_path / "s.yaml").write_text(
        "base: base.yaml\npoints:\n  - {name: bare, set: {lidar.target: bare}}\n"
        "  - {name: snow, set: {lidar.target: flat_snow, lidar.density: 300, lidar.optical_diameter: 0.0005}}\n"
    )
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", "sweep", "s.yaml", "--cores", "2"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    folder = tmp_path / "runs" / "sweeps" / "s"
    rows = {row["run"]: row for row in csv.DictReader((folder / "summary.csv").open())}
    assert set(rows) == {"bare", "snow"}
    estimators = ("first_return", "peak", "gaussian_fit", "median", "centroid")
    range_bin_cm = 100 * 0.005
    assert all(abs(float(rows["bare"][e])) < 0.2 * range_bin_cm for e in estimators), rows["bare"]
    assert all(float(rows["snow"][e]) > 0 for e in estimators), rows["snow"]
    assert len(list(csv.DictReader((folder / "biases.csv").open()))) == 2 * 3 * 5
    assert (folder / "poster.png").stat().st_size > 10_000
    report = (folder / "report.html").read_text()
    assert "lidar range biases" in report and "<table" in report


def test_the_roulette_cap_reaches_the_render_and_is_checked(tmp_path):
    """lidar.path_max_survival goes to the shot's render: flat snow at caps 0.999 and 0.9999 draws other paths
    (the impulse responses differ) around the same return (apparent reflectance 0.978 and 0.980, within 3 %:
    roulette is unbiased; at 0.99 a render this short reads 0.835, the rare heavy paths it needs not drawn),
    the summary records the cap, and a cap that is no cap (1) or kills paths fast (0.5) is refused by name."""
    reflectance = {}
    impulses = {}
    for cap in (0.999, 0.9999):
        name = f"cap{cap}".replace(".", "_")
        cfg = lidar_config(tmp_path, name, target="flat_snow", path_max_survival=cap, iterations=16, tail_range=0.5)
        run_stages(cfg, STAGES, quiet=True)
        out = tmp_path / "runs" / name / "lidar"
        summary = json.loads((out / "summary.json").read_text())
        assert summary["config"]["path_max_survival"] == cap
        reflectance[cap] = summary["channels"][0]["apparent_reflectance"]
        impulses[cap] = np.load(out / "waveform.npz")["impulse"]
    assert not np.array_equal(impulses[0.999], impulses[0.9999])
    assert reflectance[0.999] == pytest.approx(reflectance[0.9999], rel=0.03)
    for bad in (1.0, 0.5):
        with pytest.raises(ConfigError, match="lidar.path_max_survival"):
            lidar_config(tmp_path, "bad", path_max_survival=bad)

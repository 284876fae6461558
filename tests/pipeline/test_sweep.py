"""Sweeps: sweep files are validated before anything runs, and the Snakemake workflow runs each point
through the stage runner, does nothing the second time and re-runs only a changed point."""

from __future__ import annotations

import csv
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.sweep import SweepError, load_sweep, prepare
from render.output.summary import write_summary

needs_snakemake = pytest.mark.skipif(importlib.util.find_spec("snakemake") is None, reason="snakemake not installed")

# A box of snow with no geometry and no reference stage: a point runs in about a second.
TINY_BASE = """\
threads: 1
scene:
  media:
    snow: {preset: thesis_set_1, boundary: "null"}
  objects:
    - {name: cube, shape: box, medium: snow}
  sun: {elevation_deg: 45.0, kind: directional}
  camera: {width: 16, height: 12}
  film: {mode: transient, temporal_bins: 6, window: auto}
render: {iterations: 2, light_paths_per_iteration: 1000}
reference: {steady: false, transient: false}
composite: {video_min_height: 64}
"""

TINY_SWEEP = """\
description: three optical sets on a box
base: base.yaml
set: {{runs_dir: {runs}}}
points:
  - name: set1
    set: {{scene.media.snow.preset: thesis_set_1}}
  - name: set6
    set: {{scene.media.snow.preset: thesis_set_6}}
  - name: firn
    set: {{scene.media.snow.preset: {firn}}}
"""


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture
def base(tmp_path):
    return write(tmp_path / "base.yaml", TINY_BASE)


def sweep_error(tmp_path, text) -> str:
    with pytest.raises(SweepError) as caught:
        load_sweep(write(tmp_path / "bad.yaml", text))
    return str(caught.value)


# ---------------------------------------------------------------- validation, before anything runs


def test_unknown_key_in_the_sweep_file_names_the_file_point_and_key(tmp_path, base):
    message = sweep_error(tmp_path, "base: base.yaml\npoints:\n  - name: a\n    sett: {seed: 2}\n")
    assert message.startswith(f"{tmp_path / 'bad.yaml'}: point 'a': sett: unknown key")
    assert "\n" not in message
    message = sweep_error(tmp_path, "base: base.yaml\npoint: []\n")
    assert "point: unknown key" in message


def test_override_of_a_missing_config_key_names_the_point_and_key(tmp_path, base):
    message = sweep_error(tmp_path, "base: base.yaml\npoints:\n  - name: a\n    set: {render.iteratons: 4}\n")
    assert message == (
        f"{tmp_path / 'bad.yaml'}: point 'a': render.iteratons: the base config has no key "
        "'iteratons' under render (did you mean 'iterations'?)"
    )
    # A mistyped medium id would silently add a medium: it is an error too.
    message = sweep_error(tmp_path, "base: base.yaml\npoints:\n  - name: b\n    set: {scene.media.snw.preset: x}\n")
    assert "point 'b': scene.media.snw.preset: the base config has no key 'snw' under scene.media" in message


def test_invalid_value_and_duplicate_names(tmp_path, base):
    message = sweep_error(tmp_path, "base: base.yaml\npoints:\n  - {name: a, set: [render.iterations=0]}\n")
    assert f"{tmp_path / 'bad.yaml'}: point 'a': render.iterations: value 0 is not allowed" in message
    message = sweep_error(tmp_path, "base: base.yaml\npoints:\n  - {name: a}\n  - {name: a, set: {seed: 3}}\n")
    assert message == f"{tmp_path / 'bad.yaml'}: point 'a' appears twice (points 1 and 2); point names must be unique"
    message = sweep_error(tmp_path, "base: base.yaml\npoints:\n  - {name: a, set: {threads: 8}}\n")
    assert "point 'a': threads: cannot be set by a sweep point" in message


def test_grid_makes_every_combination(tmp_path, base):
    write(tmp_path / "grid.yaml", "base: base.yaml\ngrid:\n  seed: [1, 2]\n  render.iterations: {few: 2, many: 8}\n")
    sweep = load_sweep(tmp_path / "grid.yaml")
    assert [p.name for p in sweep.points] == [
        "seed-1_iterations-few",
        "seed-1_iterations-many",
        "seed-2_iterations-few",
        "seed-2_iterations-many",
    ]
    assert sweep.points[3].config.render.iterations == 8 and sweep.points[3].config.seed == 2
    assert sweep.points[0].config.name == "grid-seed-1_iterations-few"


def test_the_shipped_sweeps_are_valid():
    sweeps = sorted((Path(__file__).parents[2] / "configs" / "sweeps").glob("*.yaml"))
    loaded = [load_sweep(path) for path in sweeps if path.name != "base_small.yaml"]
    assert len(loaded) >= 4 and all(len(s.points) >= 3 for s in loaded)


def test_point_configs_are_rewritten_only_when_they_change(tmp_path, base, monkeypatch):
    monkeypatch.chdir(tmp_path)
    sweep_file = write(tmp_path / "s.yaml", TINY_SWEEP.format(runs=tmp_path / "runs", firn="penitente_firn"))
    prepare(load_sweep(sweep_file))
    points = tmp_path / "runs" / "sweeps" / "s" / "points"
    before = {p.name: p.stat().st_mtime_ns for p in points.iterdir()}
    prepare(load_sweep(sweep_file))
    assert {p.name: p.stat().st_mtime_ns for p in points.iterdir()} == before
    written = yaml.safe_load((points / "set6.yaml").read_text())
    assert written["name"] == "s-set6" and written["scene"]["media"]["snow"]["preset"] == "thesis_set_6"


def test_summary_of_points_with_missing_files_has_empty_cells(tmp_path, base, monkeypatch, caplog):
    monkeypatch.chdir(tmp_path)
    sweep_file = write(tmp_path / "s.yaml", TINY_SWEEP.format(runs=tmp_path / "runs", firn="penitente_firn"))
    paths = write_summary(prepare(load_sweep(sweep_file)))
    rows = (tmp_path / "runs" / "sweeps" / "s" / "summary.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[1].startswith("set1,thesis_set_1,")
    assert "is missing; its cells stay empty" in caplog.text
    assert paths["poster"].is_file() and paths["report"].is_file() and "error_plot" not in paths


def test_summary_flags_a_point_whose_reference_is_likely_dark(tmp_path, base, monkeypatch, caplog):
    """The reference stage records the share of light its roulette is expected to leave out (timing.json's
    ``roulette``); the summary tabulates it and warns past 0.5 % (render/scene/roulette.py)."""
    monkeypatch.chdir(tmp_path)
    text = TINY_SWEEP.format(runs=tmp_path / "runs", firn="penitente_firn")
    text = text.replace("set: {runs_dir:", "set: {reference.steady: true, runs_dir:")
    spec = prepare(load_sweep(write(tmp_path / "s.yaml", text)))
    for point, (depth, missed) in {"set1": (27, 0.0024), "firn": (3000, 0.0072)}.items():
        folder = tmp_path / "runs" / f"s-{point}" / "reference"
        folder.mkdir(parents=True)
        roulette = {"rr_depth": depth, "missed": missed, "medium": "snow (B)", "source": "reference.rr_depth"}
        (folder / "timing.json").write_text(json.dumps({"steady": None, "transient": None, "roulette": roulette}))
    write_summary(spec)
    rows = {r["point"]: r for r in csv.DictReader((tmp_path / "runs" / "sweeps" / "s" / "summary.csv").open())}
    assert float(rows["firn"]["reference_missed_share"]) == 0.0072 and rows["firn"]["reference_rr_depth"] == "3000"
    assert "point 'firn': its reference is likely 0.7 % dark (roulette from collision 3000)" in caplog.text
    assert "point 'set1': its reference is likely" not in caplog.text


# ---------------------------------------------------------------- the workflow end to end


def sweep_cli(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "pipeline", "sweep", *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def manifests(runs: Path) -> dict[str, tuple[int, str]]:
    return {
        str(p.relative_to(runs)): (p.stat().st_mtime_ns, p.read_text())
        for p in sorted(runs.glob("s-*/*/manifest.json"))
    }


@needs_snakemake
def test_sweep_runs_then_does_nothing_then_reruns_only_the_changed_point(tmp_path, base):
    runs = tmp_path / "runs"
    sweep_file = write(tmp_path / "s.yaml", TINY_SWEEP.format(runs=runs, firn="penitente_firn"))
    first = sweep_cli(str(sweep_file), "--cores", "2", cwd=tmp_path)
    assert first.returncode == 0, first.stdout[-3000:] + first.stderr[-3000:]
    folder = runs / "sweeps" / "s"
    for name in ("summary.csv", "summary.md", "summary.html", "poster.png", "report.html"):
        assert (folder / name).is_file(), name
    table = (folder / "summary.csv").read_text().splitlines()
    assert len(table) == 4 and "snow_diffuse_albedo_g" in table[0] and "render_s" in table[0]
    assert "s-set1/compare/report.html" in (folder / "report.html").read_text()
    done = manifests(runs)
    assert {k for k in done if k.endswith("compare/manifest.json")} == {
        f"s-{p}/compare/manifest.json" for p in ("set1", "set6", "firn")
    }

    second = sweep_cli(str(sweep_file), "--cores", "2", cwd=tmp_path)
    assert second.returncode == 0, second.stderr[-3000:]
    assert "Nothing to be done" in second.stdout + second.stderr
    assert manifests(runs) == done

    write(sweep_file, TINY_SWEEP.format(runs=runs, firn="fresh_snow"))
    third = sweep_cli(str(sweep_file), "--cores", "2", cwd=tmp_path)
    assert third.returncode == 0, third.stderr[-3000:]
    assert "wildcards: point=firn" in third.stdout + third.stderr
    assert "point=set1" not in third.stdout + third.stderr and "point=set6" not in third.stdout + third.stderr
    after = manifests(runs)
    assert {k: v for k, v in after.items() if not k.startswith("s-firn/")} == {
        k: v for k, v in done.items() if not k.startswith("s-firn/")
    }
    assert after["s-firn/scene/manifest.json"] != done["s-firn/scene/manifest.json"]
    assert "fresh_snow" in (folder / "summary.csv").read_text()


@needs_snakemake
@pytest.mark.skipif(
    importlib.util.find_spec("snakemake_executor_plugin_slurm") is None,
    reason="snakemake-executor-plugin-slurm not installed",
)
def test_slurm_profile_dry_run_prints_the_jobs_it_would_submit(tmp_path, base):
    sweep_file = write(tmp_path / "s.yaml", TINY_SWEEP.format(runs=tmp_path / "runs", firn="penitente_firn"))
    result = sweep_cli(str(sweep_file), "--profile", "slurm", "-n", cwd=tmp_path)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-3000:]
    assert "profiles/slurm" in output
    for point in ("set1", "set6", "firn"):
        assert f"wildcards: point={point}" in output
    assert not (tmp_path / "runs" / "s-set1").exists()


def test_cli_reports_sweep_errors_one_per_line(tmp_path, base):
    write(
        tmp_path / "bad.yaml",
        "base: base.yaml\npoints:\n  - {name: a, set: {render.iteratons: 4}}\n  - {name: b, set: {seed: -1}}\n",
    )
    result = sweep_cli("bad.yaml", cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("error: bad.yaml: point 'a': render.iteratons:")
    assert lines[1].startswith("error: bad.yaml: point 'b': seed: value -1 is not allowed")

"""The stage runner: skipping, selective re-runs, manifests and the staging-folder swap."""

from __future__ import annotations

import json

import pytest

from pipeline.config import load_config
from pipeline.manifest import file_sha256
from pipeline.runner import Stage, StageError, run_stages


def make_pipeline(calls: list[str]):
    """Three small real stages: a -> b -> c, keyed on different config keys."""

    def stage_a(ctx):
        calls.append("a")
        (ctx.out_dir / "a.txt").write_text(f"seed={ctx.config.seed}\n")
        return {"seed": ctx.config.seed}

    def stage_b(ctx):
        calls.append("b")
        text = (ctx.inputs["a"] / "a.txt").read_text()
        (ctx.out_dir / "b.txt").write_text(text.upper())

    def stage_c(ctx):
        calls.append("c")
        text = (ctx.inputs["b"] / "b.txt").read_text()
        (ctx.out_dir / "sub").mkdir()
        (ctx.out_dir / "sub" / "c.txt").write_text(text + f"threads={ctx.config.threads}\n")

    return [
        Stage("a", stage_a, ("seed",)),
        Stage("b", stage_b, (), upstream=("a",)),
        Stage("c", stage_c, ("threads",), upstream=("b",)),
    ]


@pytest.fixture
def config_file(tmp_path):
    path = tmp_path / "toy.yaml"
    path.write_text(f"seed: 1\nthreads: 1\nruns_dir: {tmp_path / 'runs'}\n")
    return path


def test_second_run_skips_everything(config_file):
    calls: list[str] = []
    stages = make_pipeline(calls)
    cfg = load_config(config_file)
    first = run_stages(cfg, stages, quiet=True)
    assert [r.status for r in first] == ["ran"] * 3 and calls == ["a", "b", "c"]
    second = run_stages(cfg, stages, quiet=True)
    assert [r.status for r in second] == ["skipped"] * 3 and calls == ["a", "b", "c"]


def test_changing_a_key_reruns_that_stage_and_its_dependents_only(config_file):
    calls: list[str] = []
    stages = make_pipeline(calls)
    run_stages(load_config(config_file), stages, quiet=True)
    calls.clear()
    results = run_stages(load_config(config_file, ["threads=2"]), stages, quiet=True)
    assert calls == ["c"] and [r.status for r in results] == ["skipped", "skipped", "ran"]
    calls.clear()
    run_stages(load_config(config_file, ["seed=2", "threads=2"]), stages, quiet=True)
    assert calls == ["a", "b", "c"]


def test_manifest_records_hashes_and_is_checked(config_file):
    calls: list[str] = []
    stages = make_pipeline(calls)
    cfg = load_config(config_file)
    results = run_stages(cfg, stages, quiet=True)
    c_dir = results[2].out_dir
    manifest = json.loads((c_dir / "manifest.json").read_text())
    assert manifest["outputs"]["sub/c.txt"]["sha256"] == file_sha256(c_dir / "sub" / "c.txt")
    assert set(manifest["inputs"]) == {"b"} and manifest["config_keys"] == ["threads"]
    assert manifest["git_revision"] and manifest["seconds"] >= 0
    # A damaged output makes the stage out of date.
    (c_dir / "sub" / "c.txt").write_text("tampered\n")
    calls.clear()
    run_stages(cfg, stages, quiet=True)
    assert calls == ["c"]


def test_failed_stage_leaves_previous_output_and_no_staging(config_file, tmp_path):
    calls: list[str] = []
    stages = make_pipeline(calls)
    cfg = load_config(config_file)
    run_stages(cfg, stages, quiet=True)

    def broken(ctx):
        (ctx.out_dir / "half.txt").write_text("partial")
        raise RuntimeError("boom")

    stages[2] = Stage("c", broken, ("threads",), upstream=("b",))
    with pytest.raises(RuntimeError, match="boom"):
        run_stages(load_config(config_file, ["threads=3"]), stages, quiet=True)
    run_root = tmp_path / "runs" / "toy"
    assert (run_root / "c" / "sub" / "c.txt").read_text().endswith("threads=1\n")
    assert not list(run_root.glob(".*staging*")) and not (run_root / "c" / "half.txt").exists()


def test_only_selected_stage_runs_and_needs_finished_upstream(config_file):
    calls: list[str] = []
    stages = make_pipeline(calls)
    cfg = load_config(config_file)
    with pytest.raises(StageError, match="needs the output of a"):
        run_stages(cfg, stages, only=["b"], quiet=True)
    run_stages(cfg, stages, quiet=True)
    calls.clear()
    results = run_stages(cfg, stages, only=["b"], force=True, quiet=True)
    assert calls == ["b"] and [r.name for r in results] == ["b"]
    with pytest.raises(StageError, match="unknown stage 'z'"):
        run_stages(cfg, stages, only=["z"], quiet=True)


def test_geometry_seed_holds_the_field_while_the_run_seed_changes(tmp_path):
    """geometry.seed keeps one grown field across runs whose root seed differs (independent renders of one
    field, as benchmarks/crop_quality.py needs); unset, the root seed grows another field."""
    import numpy as np

    from pipeline.stages import STAGES

    path = tmp_path / "tiny.yaml"
    path.write_text(
        "extends: [presets/sites/tapado.yaml]\n"
        f"runs_dir: {tmp_path / 'runs'}\n"
        "geometry:\n  grid_cells: 64\n  days: 2\n  snapshots: 2\n  preview_size: 128\n"
    )

    def field(name: str, *overrides: str) -> np.ndarray:
        cfg = load_config(path, [f"name={name}", *overrides])
        (result,) = [r for r in run_stages(cfg, STAGES, only=("geometry",), quiet=True) if r.name == "geometry"]
        with np.load(result.out_dir / "heightfield.npz") as grown:
            return grown["height"]

    held_1 = field("held_1", "seed=1", "geometry.seed=5")
    held_2 = field("held_2", "seed=2", "geometry.seed=5")
    root_5 = field("root_5", "seed=5")
    root_2 = field("root_2", "seed=2")
    assert np.array_equal(held_1, held_2) and np.array_equal(held_1, root_5)
    assert np.abs(root_2 - root_5).max() > 1e-3

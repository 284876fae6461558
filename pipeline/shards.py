"""`pipeline run CONFIG --shards K --profile slurm`: one render's iterations over many machines through
the Snakemake workflow ``workflow/shards.smk``.

The workflow has one ``prepare`` job (the stages before the render: geometry, scene), K ``shard`` jobs
(`pipeline shard CONFIG --index k --shards K`, each writing its float64 sums to
``runs/<name>/.render.shards/shard-k/``) and one ``merge`` job (`pipeline run CONFIG --shards K`, whose
render stage finds every shard done, merges them in index order and runs the stages after it).
Without --profile, `pipeline run --shards K` renders the shards one after another in this process.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import yaml

from pipeline.runner import run_dir, shards_dir
from pipeline.sweep import SweepError, run_workflow, snakemake_command, write_if_changed

SHARDS_SNAKEFILE = Path(__file__).resolve().parent / "workflow" / "shards.smk"
# The shard rule's own resources (shards.smk reads them from the workflow config); a profile's
# set-resources wins. Memory in MB, runtime in minutes.
SHARD_RESOURCES = {"mem_mb": 8000, "runtime": 120}


def prepare_shards(config, config_path: Path, overrides: list[str], shards: int, workdir: Path | None = None) -> Path:
    """Write the shards workflow's config under ``runs/<name>/.workflow/``; return its path."""
    from pipeline.stages import STAGES

    workdir = (workdir or Path.cwd()).resolve()
    base = (workdir / run_dir(config)).resolve()
    folder = base / ".workflow"
    before_render = [s.name for s in STAGES[: [s.name for s in STAGES].index("render")] if s.enabled(config)]
    last = [s.name for s in STAGES if s.enabled(config)][-1]
    spec = {
        "run": config.name,
        "folder": str(folder),
        "workdir": str(workdir),
        "python": sys.executable,
        "config": str((workdir / config_path).resolve()),
        "overrides": list(overrides),
        "shards": shards,
        "threads": config.threads or 1,
        "resources": {"shard": SHARD_RESOURCES},
        "prepare_stages": before_render,
        "prepared": str(base / "scene" / "manifest.json"),  # the scene stage always runs before the render
        "shards_dir": str(shards_dir(base, "render")),
        "done": str(base / last / "manifest.json"),
    }
    workflow_yaml = folder / "shards.yaml"
    write_if_changed(
        workflow_yaml,
        "# Written by `python -m pipeline run --shards K --profile ...`: the shards workflow's config.\n"
        + yaml.safe_dump(spec, sort_keys=False),
    )
    return workflow_yaml


def run_shards(
    config,
    config_path: Path,
    overrides: list[str],
    shards: int,
    profile: str | None,
    cores: str | None = None,
    dry_run: bool = False,
) -> int:
    """Run the shards workflow through Snakemake (it prints to this terminal); its exit code."""
    if importlib.util.find_spec("snakemake") is None:
        raise SweepError("snakemake is not installed in this environment; install requirements.lock into it")
    workflow_yaml = prepare_shards(config, config_path, overrides, shards)
    command = snakemake_command(workflow_yaml, cores, profile, dry_run, snakefile=SHARDS_SNAKEFILE)
    threads = config.threads or 1
    return run_workflow(
        command, profile, {"shard": {"threads": threads, **SHARD_RESOURCES}, "merge": {"threads": threads}}, dry_run
    )

"""Command-line interface: ``python -m pipeline {validate,run,stages,sweep} ...``."""

from __future__ import annotations

import json
import logging
import sys
import traceback
from pathlib import Path
from typing import NoReturn

import typer
import yaml

from common.log import setup_logging
from pipeline.config import ConfigError, load_config
from pipeline.lock import RunFolderBusy, hold_run_folder
from pipeline.runner import StageError, StageFailed, run_dir, run_stages
from pipeline.space import NotEnoughSpace

app = typer.Typer(
    help="Penitentes pipeline: geometry -> scene -> render (ours, reference) -> composite -> compare.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
log = logging.getLogger("pipeline")

CONFIG_ARG = typer.Argument(..., help="YAML config file.", exists=False, dir_okay=False)
SET_OPTION = typer.Option(
    None, "--set", "-s", help="Override one key, e.g. --set render.iterations=16 (value in YAML syntax). Repeatable."
)


# Exit codes of `pipeline run` (docs/guide/configs.md): 2 is also typer's for a bad command line.
EXIT_FAILED = 1  # a stage failed, or the run could not start (a missing upstream stage, input file)
EXIT_CONFIG = 2  # the config or the command line is wrong
EXIT_BUSY = 3  # --no-wait, and another process holds the run folder
EXIT_NO_SPACE = 4  # the stages to run would not fit on the run folder's disk; nothing ran
EXIT_INTERRUPTED = 130  # Ctrl-C


def _load_or_exit(config_path: Path, overrides: list[str] | None):
    try:
        return load_config(config_path, overrides or [])
    except ConfigError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=2) from None


@app.command()
def validate(
    config: Path | None = typer.Argument(None, help="YAML config file (not needed with --explain)."),
    overrides: list[str] | None = SET_OPTION,
    explain: str | None = typer.Option(
        None, "--explain", metavar="KEY", help="Print one key's type, default, unit and description, and exit."
    ),
) -> None:
    """Validate CONFIG and print the resolved config (bases merged, defaults filled in)."""
    if explain is not None:
        from pipeline.reference import explain as explain_key

        try:
            typer.echo(explain_key(explain), nl=False)
        except KeyError as exc:
            typer.echo(f"error: {exc.args[0]}", err=True)
            raise typer.Exit(code=2) from None
        return
    if config is None:
        typer.echo("error: give a CONFIG file to validate (or --explain KEY)", err=True)
        raise typer.Exit(code=2)
    cfg = _load_or_exit(config, overrides)
    typer.echo(yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False), nl=False)
    from geometry.ablation import config_warnings

    for warning in config_warnings(cfg.geometry):
        typer.echo(f"warning: {warning}", err=True)
    typer.echo(f"# {config}: valid", err=True)


@app.command()
def docs() -> None:
    """Regenerate docs/config-reference.md from the config schema."""
    from pipeline.reference import write

    typer.echo(f"wrote {write()}")


@app.command()
def stages() -> None:
    """List the pipeline's stages in order, with what each depends on."""
    from pipeline.stages import STAGES

    for stage in STAGES:
        typer.echo(f"{stage.name:<10} {stage.description}")
        typer.echo(
            f"{'':<10} config keys: {', '.join(stage.config_keys)}; upstream: {', '.join(stage.upstream) or '-'}"
        )


@app.command()
def run(
    config: Path = CONFIG_ARG,
    stage: list[str] | None = typer.Option(None, "--stage", help="Run only this stage (repeatable)."),
    force: bool = typer.Option(False, "--force", help="Re-run the selected stages even if up to date."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars; warnings and errors only."),
    resume: bool = typer.Option(
        False, "--resume", help="Continue interrupted progressive renders from their last checkpoint."
    ),
    overrides: list[str] | None = SET_OPTION,
    shards: int = typer.Option(
        1, "--shards", min=1, help="Split the render's iterations into K shards, merged exactly (float64 sums)."
    ),
    profile: str | None = typer.Option(
        None, "--profile", help="With --shards: run the shards through Snakemake with this profile (default, slurm)."
    ),
    cores: str | None = typer.Option(None, "--cores", "-c", help="With --profile: cores for local jobs."),
    dry_run: bool = typer.Option(False, "--dry-run", "-n", help="With --profile: print the jobs; run nothing."),
    no_wait: bool = typer.Option(
        False, "--no-wait", help="Refuse at once (exit 3) when another run holds runs/<name>/, instead of waiting."
    ),
    debug: bool = typer.Option(
        False, "--debug", help="On a failure, print the traceback too (it is always in runs/<name>/run.log)."
    ),
) -> None:
    """Run the pipeline on CONFIG. Finished stages whose inputs did not change are skipped.

    Exit codes: 0 done, 1 a stage failed, 2 a bad config or option, 3 the run folder is in use (--no-wait),
    4 not enough disk space (nothing ran), 130 interrupted."""
    setup_logging(quiet)
    cfg = _load_or_exit(config, overrides)
    from pipeline.stages import STAGES

    if shards > 1 and cfg.render.time_budget_s is not None:
        typer.echo(
            "error: render.time_budget_s and --shards do not mix (a shard runs a fixed range of render.iterations); "
            "set render.time_budget_s: null or run without --shards",
            err=True,
        )
        raise typer.Exit(code=2)
    if shards > cfg.render.iterations:
        typer.echo(f"error: --shards {shards} exceeds render.iterations = {cfg.render.iterations}", err=True)
        raise typer.Exit(code=2)
    if profile is not None or dry_run:
        from pipeline.shards import run_shards
        from pipeline.slurm import ClusterError
        from pipeline.sweep import SweepError

        try:
            code = run_shards(cfg, config, list(overrides or []), shards, profile, cores, dry_run)
        except (SweepError, ClusterError) as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(code=2) from None
        if code != 0:
            typer.echo(
                f"error: snakemake failed (exit {code}); logs in {run_dir(cfg) / '.workflow' / 'logs'}/", err=True
            )
        raise typer.Exit(code=code)
    try:
        results = run_stages(
            cfg, STAGES, only=stage, force=force, quiet=quiet, resume=resume, shards=shards, wait=not no_wait
        )
    except RunFolderBusy as exc:
        _fail(exc, EXIT_BUSY, debug)
    except NotEnoughSpace as exc:
        _fail(exc, EXIT_NO_SPACE, debug)
    except StageFailed as exc:
        _fail(exc, EXIT_FAILED, debug, exc.__cause__)
    except (StageError, ConfigError, ValueError, OSError) as exc:
        _fail(exc, EXIT_FAILED, debug)
    except KeyboardInterrupt:
        typer.echo("interrupted: finished stages are kept; the interrupted one left nothing behind", err=True)
        raise typer.Exit(code=EXIT_INTERRUPTED) from None
    typer.echo(f"\nRun '{cfg.name}': outputs under {run_dir(cfg).resolve()}")
    for result in results:
        took = f"{result.seconds:7.1f} s" if result.status == "ran" else "        "
        typer.echo(f"  {result.name:<10} {result.status:<9} {took}  {result.out_dir}")
        if result.summary and result.status == "ran":
            typer.echo("             " + json.dumps(result.summary, default=str)[:300])


def _fail(exc: BaseException, code: int, debug: bool, cause: BaseException | None = None) -> NoReturn:
    """One line on stderr for ``exc`` (and with ``debug`` the traceback of ``cause`` or ``exc``), then exit."""
    if debug:
        traceback.print_exception(cause or exc, file=sys.stderr)
    typer.echo(f"error: {exc}", err=True)
    raise typer.Exit(code=code) from None


@app.command()
def shard(
    config: Path = CONFIG_ARG,
    index: int = typer.Option(..., "--index", min=0, help="This shard's index k in [0, K)."),
    shards: int = typer.Option(..., "--shards", min=1, help="K, the number of shards of the render."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars; warnings and errors only."),
    overrides: list[str] | None = SET_OPTION,
) -> None:
    """Render one shard of CONFIG's render into runs/<name>/.render.shards/ (a job of --shards K --profile)."""
    setup_logging(quiet)
    cfg = _load_or_exit(config, overrides)
    if index >= shards:
        typer.echo(f"error: --index {index} must be below --shards {shards}", err=True)
        raise typer.Exit(code=2)
    from pipeline.runner import shards_dir
    from render.ptpb.stage import run_render_shard

    base = run_dir(cfg)
    if not (base / "scene" / "manifest.json").is_file():
        typer.echo(
            f"error: {base / 'scene'} is not finished; run `pipeline run {config} --stage scene` first", err=True
        )
        raise typer.Exit(code=1)
    try:
        # Shared: the other shards run beside this one, a `pipeline run` of the same folder waits for them all.
        with hold_run_folder(base, shared=True):
            record = run_render_shard(
                base / "scene", cfg.render_settings(), shards_dir(base, "render"), index, shards, quiet=quiet
            )
    except (ValueError, OSError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    typer.echo(f"shard {index + 1}/{shards}: iterations {record.get('first_iteration')}..{record.get('end_iteration')}")


@app.command(context_settings={"allow_extra_args": True})
def sweep(
    ctx: typer.Context,
    sweep_file: Path = typer.Argument(..., help="Sweep YAML file (configs/sweeps/...).", dir_okay=False),
    cores: str | None = typer.Option(
        None, "--cores", "-c", help="Cores for local jobs (a number or 'all'); default: the profile's."
    ),
    profile: str | None = typer.Option(
        None, "--profile", help="Snakemake profile: a folder, or a name under profiles/ (default, slurm)."
    ),
    dry_run: bool = typer.Option(
        False, "--dry-run", "-n", help="Print the jobs Snakemake would run or submit; run nothing."
    ),
) -> None:
    """Run every point of SWEEP_FILE through the Snakemake workflow, then the sweep summary.

    Arguments after `--` go to snakemake unchanged, e.g. `-- --forcerun point`.
    """
    from pipeline.slurm import ClusterError
    from pipeline.sweep import SweepError, load_sweep, points_not_done, run_sweep

    setup_logging(quiet=True)
    try:
        spec = load_sweep(sweep_file)
        code = run_sweep(spec, cores=cores, profile=profile, dry_run=dry_run, extra=list(ctx.args))
    except (SweepError, ClusterError) as exc:
        typer.echo("\n".join(f"error: {line}" for line in str(exc).splitlines()), err=True)
        raise typer.Exit(code=2) from None
    if code != 0:
        missing = points_not_done(spec)
        not_run = f"points not run: {', '.join(missing)}; a rerun runs only those" if missing else "every point ran"
        typer.echo(
            f"error: snakemake failed (exit {code}); {not_run}; each point's log is in {spec.folder / 'logs'}/",
            err=True,
        )
        raise typer.Exit(code=code)
    if not dry_run:
        typer.echo(
            f"\nSweep '{spec.name}': {len(spec.points)} points; report: {(spec.folder / 'report.html').resolve()}"
        )


def main() -> None:
    try:
        app()
    except BrokenPipeError:
        sys.exit(1)

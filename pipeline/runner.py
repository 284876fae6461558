"""The stage runner: runs stages in order, skips the ones whose manifest matches, and never
leaves a half-written stage visible.

Each stage writes into a private staging folder ``runs/<name>/.<stage>.staging-<pid>``. Only
when the stage function has returned and its manifest is written is the folder renamed to
``runs/<name>/<stage>``. A stage killed at any moment therefore leaves either its previous
complete output or nothing, and the next run redoes exactly the unfinished stages.

A stage that can resume (the render stage) keeps its progress in ``runs/<name>/.<stage>.checkpoint/``,
outside the staging swap. The runner owns that folder's life: it is removed before a stage runs
without ``resume`` (a stale checkpoint never leaks into a fresh run) and once the stage's output
is published.

A run holds the run folder's lock (pipeline/lock.py) for as long as it writes there, logs to
``runs/<name>/run.log``, checks the free disk space against what its stages will write before it
starts them (pipeline/space.py), and turns any failure inside a stage into one ``StageFailed`` whose
message names the stage and the path; the traceback goes to the log file only.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from common.atomic import final_path, write_json_atomic
from common.log import FILE_ONLY, log_to_file
from pipeline.config import config_hash
from pipeline.lock import hold_run_folder
from pipeline.manifest import (
    MANIFEST_NAME,
    MANIFEST_VERSION,
    git_revision,
    hash_outputs,
    outputs_digest,
    outputs_intact,
    read_manifest,
)
from pipeline.space import check_space

log = logging.getLogger(__name__)


@dataclass
class StageContext:
    """What a stage function gets: the config, its output folder and its upstream folders."""

    config: Any
    out_dir: Path
    inputs: dict[str, Path]
    quiet: bool = False
    resume: bool = False
    previous_dir: Path | None = None  # the last complete output of this stage, if any (for resume)
    checkpoint_dir: Path | None = None  # survives the staging swap; holds what a resumed run continues from
    shards: int = 1  # `pipeline run --shards K`: the render splits its iterations into K shards
    shards_dir: Path | None = None  # survives the staging swap; holds the finished shards until the merge


@dataclass(frozen=True)
class Stage:
    """A pipeline stage: a plain function plus what it depends on."""

    name: str
    func: Callable[[StageContext], dict[str, Any] | None]
    config_keys: tuple[str, ...]
    upstream: tuple[str, ...] = ()
    description: str = ""
    enabled: Callable[[Any], bool] = field(default=lambda config: True)
    writes: Callable[[Any], int] = field(default=lambda config: 0)  # estimated bytes of its large arrays


@dataclass
class StageResult:
    name: str
    status: str  # "ran", "skipped" (up to date) or "disabled"
    out_dir: Path
    seconds: float = 0.0
    summary: dict[str, Any] | None = None


class StageError(RuntimeError):
    """A stage could not run; the message says which and why."""


class StageFailed(StageError):
    """A stage raised; the message names the stage, what happened and where. The original exception is
    the ``__cause__``, and its traceback is in the run's log file (``log_path``)."""

    def __init__(self, stage: str, what: str, where: str, log_path: Path) -> None:
        super().__init__(f"stage {stage} failed: {what}, {where}")
        self.stage = stage
        self.log_path = log_path


RUN_LOG = "run.log"


def run_dir(config) -> Path:
    return Path(config.runs_dir) / config.name


def checkpoint_dir(base: Path, stage: str) -> Path:
    """Where ``stage`` of the run folder ``base`` keeps its checkpoints."""
    return base / f".{stage}.checkpoint"


def shards_dir(base: Path, stage: str) -> Path:
    """Where ``stage`` of the run folder ``base`` keeps its finished shards until they are merged."""
    return base / f".{stage}.shards"


def _remove_leftovers(base: Path, stage: str) -> None:
    for leftover in base.glob(f".{stage}.staging-*"):
        shutil.rmtree(leftover, ignore_errors=True)
    for leftover in base.glob(f".{stage}.old-*"):
        shutil.rmtree(leftover, ignore_errors=True)


def _publish(staging: Path, final: Path) -> None:
    """Swap the finished staging folder in for the stage's folder."""
    old = final.with_name(f".{final.name}.old-{os.getpid()}")
    if final.exists():
        os.replace(final, old)
    os.replace(staging, final)
    shutil.rmtree(old, ignore_errors=True)


def _failure(stage: str, exc: BaseException, staging: Path, final: Path, log_path: Path) -> StageFailed:
    """``exc``, raised while ``stage`` wrote into ``staging``, as one line that names the path."""
    if isinstance(exc, OSError) and exc.strerror:
        what = exc.strerror  # "No space left on device"; the path follows
    elif isinstance(exc, (OSError, ValueError, RuntimeError)) and str(exc):
        what = str(exc)  # numpy's "Not enough free space to write N bytes", our own errors
    else:
        what = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    filename = exc.filename if isinstance(exc, OSError) else None
    if filename:
        path = final_path(os.fsdecode(filename))  # the file being written, not its temporary name
        if path.is_relative_to(staging):  # the staging folder is gone; name the file as it would be published
            path = final / path.relative_to(staging)
        where = f"at {path}"
    else:
        where = f"writing {final}"
    return StageFailed(stage, what, f"{where} ({final} is as before the run; traceback in {log_path})", log_path)


def _planned(config, stages: Sequence[Stage], only: Sequence[str] | None, force: bool) -> list[Stage]:
    """The selected stages that will probably run: those without a manifest of the current config, and
    those downstream of one that runs. Only a guess for the space check (it reads no outputs): a stage
    whose outputs turn out damaged is checked again just before it starts."""
    base = run_dir(config)
    planned: list[Stage] = []
    running: set[str] = set()
    for stage in stages:
        if not stage.enabled(config) or (only is not None and stage.name not in only):
            continue
        if (
            force
            or not _made_from_config(config, stage, read_manifest(base / stage.name))
            or running.intersection(stage.upstream)
        ):
            planned.append(stage)
            running.add(stage.name)
    return planned


def _made_from_config(config, stage: Stage, manifest: dict | None) -> bool:
    """Whether a stage's manifest records the current config of the keys the stage reads."""
    return manifest is not None and manifest.get("config_hash") == config_hash(config, stage.config_keys)


def stage_status(config, stage: Stage, inputs_digests: dict[str, str]) -> tuple[bool, dict | None]:
    """Whether the stage's finished output matches the current config and inputs."""
    final = run_dir(config) / stage.name
    manifest = read_manifest(final)
    if manifest is None:
        return False, None
    up_to_date = (
        _made_from_config(config, stage, manifest)
        and manifest.get("inputs") == inputs_digests
        and outputs_intact(final, manifest)
    )
    return up_to_date, manifest


def run_stages(
    config,
    stages: Sequence[Stage],
    only: Sequence[str] | None = None,
    force: bool = False,
    quiet: bool = False,
    resume: bool = False,
    shards: int = 1,
    wait: bool = True,
    on_wait: Callable[[str], None] | None = None,
) -> list[StageResult]:
    """Run ``stages`` (already in dependency order) for ``config``; return what happened to each.

    ``only`` restricts the run to the named stages; their upstream stages must be finished.
    ``force`` re-runs the selected stages even when their manifests match.
    ``shards`` splits the render's iterations (render/ptpb/split.py); finished shards are kept in
    ``.<stage>.shards/`` until the stage is published.
    While another process holds the run folder, wait for it (``on_wait`` gets the message that names
    it) or, with ``wait=False``, raise ``pipeline.lock.RunFolderBusy``. ``NotEnoughSpace`` when the
    stages to run would not fit on the disk; ``StageFailed`` when a stage raises.
    """
    by_name = {s.name: s for s in stages}
    for name in only or ():
        if name not in by_name:
            raise StageError(f"unknown stage '{name}'; the stages are: {', '.join(by_name)}")
    base = run_dir(config)
    with hold_run_folder(base, wait=wait, on_wait=on_wait), log_to_file(base / RUN_LOG):
        log.info("run '%s' in %s", config.name, base)
        check_space(base, {s.name: s.writes(config) for s in _planned(config, stages, only, force)}, config)
        return _run_locked(config, stages, by_name, only, force, quiet, resume, shards)


def _run_locked(
    config,
    stages: Sequence[Stage],
    by_name: dict[str, Stage],
    only: Sequence[str] | None,
    force: bool,
    quiet: bool,
    resume: bool,
    shards: int,
) -> list[StageResult]:
    base = run_dir(config)
    log_path = base / RUN_LOG
    digests: dict[str, str] = {}
    results: list[StageResult] = []
    for stage in stages:
        final = base / stage.name
        selected = only is None or stage.name in only
        if not stage.enabled(config):
            results.append(StageResult(stage.name, "disabled", final))
            continue
        missing = [u for u in stage.upstream if u in by_name and by_name[u].enabled(config) and u not in digests]
        if missing and not selected:
            continue  # neither run nor up to date; only a selected stage needs its upstream finished
        if missing:
            raise StageError(
                f"stage '{stage.name}' needs the output of {', '.join(missing)}, which is not finished; "
                f"run without --stage first"
            )
        inputs = {u: digests[u] for u in stage.upstream if u in digests}
        up_to_date, manifest = stage_status(config, stage, inputs)
        if not selected:
            if up_to_date and manifest is not None:
                digests[stage.name] = manifest["outputs_digest"]
            continue
        progress_dir = checkpoint_dir(base, stage.name)
        if up_to_date and not force and manifest is not None:
            log.info("stage %s is up to date (%s)", stage.name, final)
            digests[stage.name] = manifest["outputs_digest"]
            # What killed runs left: their staging folders, and a checkpoint of a run killed after publishing.
            _remove_leftovers(base, stage.name)
            shutil.rmtree(progress_dir, ignore_errors=True)
            results.append(StageResult(stage.name, "skipped", final, summary=manifest.get("summary")))
            continue
        check_space(base, {stage.name: stage.writes(config)}, config)  # others may have filled the disk since
        _remove_leftovers(base, stage.name)
        if not resume:
            shutil.rmtree(progress_dir, ignore_errors=True)
        staging = base / f".{stage.name}.staging-{os.getpid()}"
        staging.mkdir(parents=True)
        log.info("stage %s: running", stage.name)
        started = datetime.now(UTC)
        t0 = time.perf_counter()
        context = StageContext(
            config=config,
            out_dir=staging,
            inputs={u: base / u for u in stage.upstream if u in digests},
            quiet=quiet,
            resume=resume,
            previous_dir=final if final.exists() else None,
            checkpoint_dir=progress_dir,
            shards=shards,
            shards_dir=shards_dir(base, stage.name),
        )
        try:
            summary = stage.func(context) or {}
            seconds = time.perf_counter() - t0
            outputs = hash_outputs(staging)
            record = {
                "version": MANIFEST_VERSION,
                "stage": stage.name,
                "run": config.name,
                "config_keys": list(stage.config_keys),
                "config_hash": config_hash(config, stage.config_keys),
                "inputs": inputs,
                "outputs": outputs,
                "outputs_digest": outputs_digest(outputs),
                "git_revision": git_revision(),
                "started_utc": started.isoformat(timespec="seconds"),
                "seconds": round(seconds, 3),
                "summary": summary,
            }
            write_json_atomic(staging / MANIFEST_NAME, record)
        except Exception as exc:
            shutil.rmtree(staging, ignore_errors=True)
            failure = _failure(stage.name, exc, staging, final, log_path)
            log.error("%s", failure, exc_info=exc, extra={FILE_ONLY: True})
            raise failure from exc
        except BaseException:  # Ctrl-C, SystemExit: nothing to explain, nothing left behind
            shutil.rmtree(staging, ignore_errors=True)
            raise
        _publish(staging, final)
        shutil.rmtree(progress_dir, ignore_errors=True)  # the published output supersedes it
        shutil.rmtree(shards_dir(base, stage.name), ignore_errors=True)
        digests[stage.name] = record["outputs_digest"]
        log.info("stage %s: done in %.1f s -> %s", stage.name, seconds, final)
        results.append(StageResult(stage.name, "ran", final, seconds, summary))
    return results

"""Config sweeps: runs of the pipeline that differ in a few keys, run by the Snakemake workflow.

A sweep file names a base config and either a list of points or a grid of overrides:

    description: the thesis's six optical sets
    base: base_small.yaml          # resolved next to the sweep file, then in configs/
    threads: 1                     # C++ core threads per point (the Snakemake rule's threads)
    set: {render.iterations: 8}    # overrides for every point
    points:
      - name: set1
        set: {scene.media.snow.preset: thesis_set_1}

    grid:                          # instead of points: every combination of the values
      scene.media.snow.physical.optical_radius: [0.0005, 0.001]
      scene.media.snow.physical.density: {light: 350, dense: 550}   # a mapping names its values

Overrides are dotted keys with the meaning of ``--set key=value`` (``set`` may also be a list of
``key=value`` strings), and every key must exist in the base config. A point's run is
``<sweep>-<point>`` and writes into ``runs/<that>/``. Its resolved config goes to
``runs/sweeps/<sweep>/points/<point>.yaml`` and is rewritten only when its content changes, so
Snakemake's modification-time check re-runs exactly the points that changed; inside a point the
stage runner's manifests skip the stages whose inputs did not change.

``ground_truth: <point>`` measures every point's errors against that point's reference renders
instead of against its own (equal-time comparisons). In the error-against-time plot a point that
renders its own reference then stands for the reference renderer, any other point for ours.

``python -m pipeline.sweep runs/sweeps/<sweep>/workflow.yaml`` (the workflow's summary rule) writes the sweep
summary: the table (CSV, Markdown, HTML), the poster grid, the error-against-time plot and ``report.html``
(render/output/summary.py), or for a sweep whose points end in the lidar stage the table of range biases
(render/lidar/table.py).
"""

from __future__ import annotations

import difflib
import importlib.util
import itertools
import json
import logging
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from pydantic import Field, ValidationError, field_validator

from common.atomic import write_text_atomic
from common.paths import CONFIGS_DIR, PROJECT_ROOT
from pipeline.config import (
    ConfigError,
    apply_overrides,
    format_key_path,
    format_validation_error,
    load_raw,
    parse_override,
    subtree,
)
from pipeline.schema import Config
from pipeline.schema.base import StrictModel

log = logging.getLogger(__name__)

SNAKEFILE = Path(__file__).resolve().parent / "workflow" / "Snakefile"
PROFILES_DIR = PROJECT_ROOT / "profiles"
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"
MAX_POINT_NAME = 80  # characters of a point name
# The point rule's own resources (rules/point.smk reads them from the workflow config); a profile's
# set-resources wins. Memory in MB, runtime in minutes.
POINT_RESOURCES = {"mem_mb": 4000, "runtime": 60}
# Keys the sweep itself decides for every point.
RESERVED_KEYS = {
    "name": "the sweep names each run '<sweep>-<point>'",
    "threads": "threads come from the sweep's 'threads' key (or Snakemake's set-threads)",
}


class SweepError(ConfigError):
    """A sweep file that cannot be used; one line per problem, each naming the file, point and key."""


def _as_assignments(value: Any) -> list[str]:
    """``{key: value}`` or ``["key=value", ...]`` as ``--set`` strings."""
    if value is None:
        return []
    if isinstance(value, dict):
        # JSON is YAML, so parse_override reads each value back unchanged.
        return [f"{key}={json.dumps(item)}" for key, item in value.items()]
    if isinstance(value, list) and all(isinstance(item, str) for item in value):
        return list(value)
    raise ValueError("must be a mapping of dotted keys to values, or a list of 'key=value' strings")


class PointSpec(StrictModel):
    """One point of a sweep file (key path points[i].<field>)."""

    name: str = Field(
        ..., pattern=NAME_PATTERN, max_length=MAX_POINT_NAME, description="Point name; its run is <sweep>-<name> [-]."
    )
    description: str = Field("", description="What the point is, for the report [-].")
    set: list[str] = Field(default_factory=list, description="Overrides of this point, dotted keys as --set [-].")

    _normalise_set = field_validator("set", mode="before")(_as_assignments)


class SweepFile(StrictModel):
    """A sweep file: a base config and a list of points or a grid of overrides."""

    name: str | None = Field(
        None, pattern=NAME_PATTERN, max_length=60, description="Sweep name; default the file stem [-]."
    )
    description: str = Field("", description="What the sweep compares, for the report [-].")
    base: str = Field(..., min_length=1, description="Base config, next to the sweep file or in configs/ [path].")
    threads: int = Field(
        1, ge=1, le=1024, description="C++ core threads of each point; the Snakemake rule's threads [-]."
    )
    set: list[str] = Field(default_factory=list, description="Overrides of every point, dotted keys as --set [-].")
    points: list[PointSpec] | None = Field(None, description="The points, each a name and its overrides [-].")
    grid: dict[str, Any] | None = Field(
        None, description="Dotted key -> list of values (or mapping label -> value); one point per combination [-]."
    )
    ground_truth: str | None = Field(
        None, description="Point whose reference renders every point's error is measured against [-]."
    )

    _normalise_set = field_validator("set", mode="before")(_as_assignments)

    @field_validator("grid")
    @classmethod
    def _grid_axes(cls, grid):
        for key, values in (grid or {}).items():
            if not isinstance(values, (list, dict)) or not values:
                raise ValueError(f"grid key '{key}' needs a non-empty list of values or mapping of label to value")
        return grid


@dataclass(frozen=True)
class SweepPoint:
    name: str
    overrides: tuple[str, ...]  # the point's own, applied after the sweep's common ones
    config: Config
    description: str = ""


@dataclass(frozen=True)
class Sweep:
    path: Path
    name: str
    description: str
    base: Path
    threads: int
    common: tuple[str, ...]
    points: tuple[SweepPoint, ...]
    ground_truth: str | None
    runs_dir: Path  # as configured: relative paths are relative to the working directory

    @property
    def folder(self) -> Path:
        """``runs/sweeps/<sweep>``: point configs, logs, Snakemake's state and the summary."""
        return self.runs_dir / "sweeps" / self.name


# ---------------------------------------------------------------- loading and validation


def _sweep_file_errors(path: Path, error: ValidationError, document: dict) -> list[str]:
    """One line per problem; ``points.2.sett`` becomes ``point 'name': sett``."""
    points = document.get("points")
    raw_points = points if isinstance(points, list) else []
    lines = []
    for line in format_validation_error(error, str(path)).splitlines()[1:]:
        match = re.match(r"\s*points\.(\d+)[.:]\s*", line)
        if match:
            index = int(match.group(1))
            given = raw_points[index] if index < len(raw_points) else None
            name = given.get("name") if isinstance(given, dict) else None
            who = f"point '{name}'" if isinstance(name, str) else f"point {index + 1}"
            line = f"{who}: {line[match.end() :]}"
        lines.append(f"{path}: {line.strip()}")
    return lines


def _resolve_base(name: str, sweep_path: Path) -> Path:
    for candidate in (sweep_path.parent / name, CONFIGS_DIR / name):
        if candidate.is_file():
            return candidate.resolve()
    raise SweepError(f"{sweep_path}: base '{name}' was found neither next to the sweep file nor in {CONFIGS_DIR}")


def _grid_points(grid: dict[str, Any], path: Path) -> list[PointSpec]:
    """Every combination of the grid's values, named ``<leaf>-<label>_<leaf>-<label>``."""
    axes = []
    for key, values in grid.items():
        labelled = values.items() if isinstance(values, dict) else [(_label(v), v) for v in values]
        axes.append([(key, str(label), value) for label, value in labelled])
    points = []
    for combination in itertools.product(*axes):
        name = "_".join(f"{key.split('.')[-1]}-{label}" for key, label, _ in combination)
        if len(name) > MAX_POINT_NAME:
            raise SweepError(
                f"{path}: grid point '{name}' has a name of {len(name)} characters, over {MAX_POINT_NAME}: shorten the "
                "grid's labels (give a key's values as a mapping, label: value) or list the points"
            )
        points.append(PointSpec(name=name, set=[f"{key}={json.dumps(value)}" for key, _, value in combination]))
    return points


def _label(value: Any) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(value)).strip("_.") or "x"


def _check_key_exists(dump: dict, keys: list[str]) -> str | None:
    """Why the dotted key is not a key of the resolved base config, or None when it is.

    The walk stops at an unset optional section (``physical: null``): pydantic checks below it.
    """
    node: Any = dump
    for depth, key in enumerate(keys):
        if not isinstance(node, dict):
            return None
        if key not in node:
            where = format_key_path(keys[:depth]) if depth else "the top level"
            close = difflib.get_close_matches(key, list(node), n=1)
            hint = f"did you mean '{close[0]}'?" if close else f"its keys: {', '.join(sorted(node)) or 'none'}"
            return f"the base config has no key '{key}' under {where} ({hint})"
        node = node[key]
    return None


def _validate_point(raw: dict, where: str) -> Config:
    try:
        return Config.model_validate(raw)
    except ValidationError as exc:
        lines = format_validation_error(exc, where).splitlines()[1:]
        raise SweepError("\n".join(f"{where}: {line.strip()}" for line in lines)) from None


def _check_overrides(assignments, base_dump: dict, where: str) -> list[str]:
    errors = []
    for assignment in assignments:
        try:
            keys, _ = parse_override(assignment)
        except ConfigError as exc:
            errors.append(f"{where}: {exc}")
            continue
        key = ".".join(keys)
        if key in RESERVED_KEYS:
            errors.append(f"{where}: {key}: cannot be set by a sweep point: {RESERVED_KEYS[key]}")
            continue
        problem = _check_key_exists(base_dump, keys)
        if problem:
            errors.append(f"{where}: {key}: {problem}")
    return errors


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file and every point's config; nothing runs before this passes."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except FileNotFoundError:
        raise SweepError(f"sweep file not found: {path}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise SweepError(f"{path}{where}: invalid YAML: {getattr(exc, 'problem', None) or exc}") from None
    if not isinstance(document, dict):
        raise SweepError(f"{path}: a sweep file must be a YAML mapping (base, points or grid, ...)")
    try:
        spec = SweepFile.model_validate(document)
    except ValidationError as exc:
        raise SweepError("\n".join(_sweep_file_errors(path, exc, document))) from None
    if (spec.points is None) == (spec.grid is None):
        raise SweepError(f"{path}: give exactly one of 'points' (a list) or 'grid' (key -> values)")
    name = spec.name or path.stem
    if not re.match(NAME_PATTERN, name):
        raise SweepError(f"{path}: the sweep name '{name}' (the file stem) must match {NAME_PATTERN}; set 'name'")
    # Exactly one of the two is set (checked above).
    if spec.points is not None:
        specs = spec.points
    elif spec.grid is not None:
        specs = _grid_points(spec.grid, path)
    if not specs:
        raise SweepError(f"{path}: the sweep has no points")
    seen: dict[str, int] = {}
    for index, point in enumerate(specs, 1):
        if point.name in seen:
            hint = "; name the grid's values with a mapping (label: value)" if spec.grid else ""
            raise SweepError(
                f"{path}: point '{point.name}' appears twice (points {seen[point.name]} and {index}); "
                f"point names must be unique{hint}"
            )
        seen[point.name] = index

    base_path = _resolve_base(spec.base, path)
    try:
        base_raw = load_raw(base_path)
    except ConfigError as exc:
        raise SweepError(f"{path}: base {base_path}: {exc}") from None
    base_raw["name"] = f"{name}-base"
    base_config = _validate_point(base_raw, f"{path}: base {spec.base}")
    errors = _check_overrides(spec.set, base_config.model_dump(mode="json"), f"{path}: set")
    if errors:
        raise SweepError("\n".join(errors))
    common_raw = apply_overrides(base_raw, spec.set)
    common_config = _validate_point(common_raw, f"{path}: set")
    common_dump = common_config.model_dump(mode="json")

    points, errors = [], []
    for point in specs:
        where = f"{path}: point '{point.name}'"
        run_name = f"{name}-{point.name}"
        if len(run_name) > 120:
            errors.append(f"{where}: the run name '{run_name}' is longer than 120 characters; shorten the names")
            continue
        problems = _check_overrides(point.set, common_dump, where)
        if problems:
            errors.extend(problems)
            continue
        raw = apply_overrides(common_raw, point.set)
        raw["name"] = run_name
        try:
            config = _validate_point(raw, where)
        except SweepError as exc:
            errors.append(str(exc))
            continue
        if config.runs_dir != common_config.runs_dir:
            errors.append(f"{where}: runs_dir: every point writes under the same runs_dir; set it in the sweep's 'set'")
            continue
        points.append(SweepPoint(point.name, tuple(point.set), config, point.description))
    if errors:
        raise SweepError("\n".join(errors))
    if spec.ground_truth is not None and spec.ground_truth not in seen:
        raise SweepError(f"{path}: ground_truth: '{spec.ground_truth}' is not a point of the sweep ({', '.join(seen)})")
    return Sweep(
        path=path,
        name=name,
        description=spec.description.strip(),
        base=base_path,
        threads=spec.threads,
        common=tuple(spec.set),
        points=tuple(points),
        ground_truth=spec.ground_truth,
        runs_dir=Path(common_config.runs_dir),
    )


# ---------------------------------------------------------------- files for Snakemake


def write_if_changed(path: Path, text: str) -> bool:
    """Write ``text`` atomically unless the file already holds it (its mtime then stays); True if written."""
    if path.is_file() and path.read_text(encoding="utf-8") == text:
        return False
    write_text_atomic(path, text)
    return True


def point_config_text(sweep: Sweep, point: SweepPoint) -> str:
    header = f"# Point '{point.name}' of sweep '{sweep.name}', written by `python -m pipeline sweep`; do not edit.\n"
    header += "".join(f"# set {item}\n" for item in (*sweep.common, *point.overrides))
    return header + yaml.safe_dump(point.config.model_dump(mode="json"), sort_keys=False)


def target_stage(sweep: Sweep) -> str:
    """The last stage enabled in every point: its manifest is each point's Snakemake output."""
    from pipeline.stages import STAGES

    enabled = [s.name for s in STAGES if all(s.enabled(p.config) for p in sweep.points)]
    return enabled[-1]


def _overrides_for_people(assignments: list[str]) -> list[tuple[str, str]]:
    """``("scene.media.snow.preset", "thesis_set_1")`` for ``scene.media.snow.preset="thesis_set_1"``."""
    pairs = []
    for assignment in assignments:
        keys, value = parse_override(assignment)
        pairs.append((".".join(keys), value if isinstance(value, str) else json.dumps(value)))
    return pairs


def _input_value(dump: dict, key: str) -> Any:
    """The point's resolved value of a dotted key, for the table (text unless a number)."""
    try:
        value = subtree(dump, key)
    except (KeyError, TypeError):
        return None
    if value is None or isinstance(value, str) or (isinstance(value, (int, float)) and not isinstance(value, bool)):
        return value
    return json.dumps(value)


def _point_spec(point: SweepPoint, input_keys: list[str]) -> dict[str, Any]:
    """What the summary needs of a point, resolved here so that it reads files only."""
    from pipeline.stages import STAGES

    dump = point.config.model_dump(mode="json")
    return {
        "overrides": list(point.overrides),
        "override_pairs": [list(pair) for pair in _overrides_for_people(list(point.overrides))],
        "description": point.description,
        "stages": [s.name for s in STAGES if s.enabled(point.config)],
        "inputs": {key: _input_value(dump, key) for key in input_keys},
    }


def prepare(sweep: Sweep, workdir: Path | None = None) -> Path:
    """Write the point configs and the workflow's config file; return the latter's path."""
    workdir = (workdir or Path.cwd()).resolve()
    folder = (workdir / sweep.folder).resolve()
    written = [
        p.name
        for p in sweep.points
        if write_if_changed(folder / "points" / f"{p.name}.yaml", point_config_text(sweep, p))
    ]
    if written:
        log.info("sweep %s: point configs written for %s", sweep.name, ", ".join(written))
    names = {p.name for p in sweep.points}
    for stale in (folder / "points").glob("*.yaml"):
        if stale.stem not in names:  # a point removed from the sweep file; its run folder stays
            stale.unlink()
    input_keys = list(dict.fromkeys(key for p in sweep.points for key, _ in _overrides_for_people(list(p.overrides))))
    spec = {
        "sweep": sweep.name,
        "sweep_file": str(sweep.path.resolve()),
        "description": sweep.description,
        "folder": str(folder),
        "workdir": str(workdir),
        "runs_dir": str((workdir / sweep.runs_dir).resolve()),
        "python": sys.executable,
        "threads": sweep.threads,
        "resources": {"point": POINT_RESOURCES},
        "target_stage": target_stage(sweep),
        "ground_truth": sweep.ground_truth,
        "common": list(sweep.common),
        "common_pairs": [list(pair) for pair in _overrides_for_people(list(sweep.common))],
        "points": {p.name: _point_spec(p, input_keys) for p in sweep.points},
    }
    workflow_yaml = folder / "workflow.yaml"
    write_if_changed(
        workflow_yaml,
        "# Written by `python -m pipeline sweep`: the Snakemake workflow's config.\n"
        + yaml.safe_dump(spec, sort_keys=False),
    )
    return workflow_yaml


def resolve_profile(profile: str | None) -> Path:
    """A profile folder as given, or by name under the project's profiles/ (default: profiles/default)."""
    candidate = Path(profile) if profile else PROFILES_DIR / "default"
    if not candidate.is_dir() and profile and (PROFILES_DIR / profile).is_dir():
        candidate = PROFILES_DIR / profile
    if not (candidate / "config.yaml").is_file():
        known = ", ".join(sorted(p.name for p in PROFILES_DIR.iterdir() if (p / "config.yaml").is_file()))
        raise SweepError(
            f"profile '{profile}' is neither a folder with a config.yaml nor one of the project's profiles ({known})"
        )
    return candidate.resolve()


def snakemake_command(
    workflow_yaml: Path,
    cores: str | None = None,
    profile: str | None = None,
    dry_run: bool = False,
    extra: tuple[str, ...] | list[str] = (),
    snakefile: Path = SNAKEFILE,
) -> list[str]:
    """The snakemake command for a workflow config (its ``folder`` is the working directory); the sweep's
    Snakefile unless ``snakefile`` names another (the shards' workflow, pipeline/shards.py)."""
    spec = yaml.safe_load(workflow_yaml.read_text(encoding="utf-8"))
    command = [
        sys.executable,
        "-m",
        "snakemake",
        "--snakefile",
        str(snakefile),
        "--directory",
        spec["folder"],
        "--configfile",
        str(workflow_yaml),
        "--workflow-profile",
        "none",
        "--profile",
        str(resolve_profile(profile)),
    ]
    if cores:
        command += ["--cores", str(cores)]
    if dry_run:
        command.append("--dry-run")
    return command + list(extra)


def run_sweep(
    sweep: Sweep,
    cores: str | None = None,
    profile: str | None = None,
    dry_run: bool = False,
    extra: tuple[str, ...] | list[str] = (),
) -> int:
    """Run the sweep's Snakemake workflow (Snakemake prints to this process's terminal); its exit code."""
    if importlib.util.find_spec("snakemake") is None:
        raise SweepError("snakemake is not installed in this environment; install requirements.lock into it")
    workflow_yaml = prepare(sweep)
    command = snakemake_command(workflow_yaml, cores, profile, dry_run, extra)
    return run_workflow(command, profile, {"point": {"threads": sweep.threads, **POINT_RESOURCES}}, dry_run)


def run_workflow(command: list[str], profile: str | None, rules: dict[str, dict[str, int]], dry_run: bool) -> int:
    """Run a snakemake command; through a SLURM profile only after the cluster checks, and watched.

    ``rules``: each rule that goes to the cluster -> its own {threads, mem_mb}."""
    from pipeline.slurm import Watch, check_profile, profile_settings, uses_slurm

    profile_dir = resolve_profile(profile)
    log.info("running %s", " ".join(command))
    if dry_run or not uses_slurm(profile_settings(profile_dir)):
        return subprocess.run(command, check=False).returncode
    check_profile(profile_dir, rules)
    return Watch(Path(command[command.index("--directory") + 1])).run(command)


def points_not_done(sweep: Sweep) -> list[str]:
    """The points whose last stage has no manifest (relative runs_dir from the working directory)."""
    from pipeline.runner import run_dir

    stage = target_stage(sweep)
    return [p.name for p in sweep.points if not (run_dir(p.config) / stage / "manifest.json").is_file()]


def write_summary(workflow_yaml: str | Path) -> dict[str, Path]:
    """The sweep summary that fits the sweep's last stage, from its workflow config (``prepare``): the lidar
    table of range biases for laser shots, else the images' table, poster and error plot."""
    spec = yaml.safe_load(Path(workflow_yaml).read_text(encoding="utf-8"))
    if spec.get("target_stage") == "lidar":
        from render.lidar.table import write_sweep_summary

        return write_sweep_summary(spec)
    from render.output.summary import write_summary as write_image_summary

    return write_image_summary(workflow_yaml)


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.sweep WORKFLOW_YAML``: the summary rule of the sweep workflow."""
    from common.log import setup_logging

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m pipeline.sweep runs/sweeps/<sweep>/workflow.yaml", file=sys.stderr)
        return 2
    setup_logging(quiet=False)
    paths = write_summary(argv[0])
    print(f"sweep summary: {paths['report']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

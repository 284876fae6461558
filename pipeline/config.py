"""Load YAML configs into the validated pydantic model, with ``extends`` and ``--set`` overrides.

A config file is a YAML mapping. It may name base files it extends:

    extends: [presets/sites/tapado.yaml, base.yaml]   # resolved next to this file, then in configs/
    render:
      iterations: 64

Bases are merged in order, then the file itself on top: mappings merge key by key, any other
value (lists included) replaces the base's. Errors name the file, or the key path, the value and
what is allowed.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from common.paths import CONFIGS_DIR


class ConfigError(ValueError):
    """A config that cannot be loaded or validated. The message is meant for people."""


def deep_merge(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    merged = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def _read_yaml_mapping(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {path}") from None
    except OSError as exc:
        raise ConfigError(f"cannot read config file {path}: {exc.strerror}") from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError(f"{path}{where}: invalid YAML: {problem}") from None
    if document is None:
        return {}
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: a config must be a YAML mapping of keys to values, got {type(document).__name__}")
    for key in document:
        if not isinstance(key, str):
            raise ConfigError(f"{path}: config keys must be strings, got {key!r}")
    return document


def _resolve_base(name: Any, including_file: Path) -> Path:
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{including_file}: 'extends' entries must be file paths, got {name!r}")
    candidates = [including_file.parent / name, CONFIGS_DIR / name]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise ConfigError(f"{including_file}: extends {name!r}, which was found neither next to it nor in {CONFIGS_DIR}")


def load_raw(path: str | Path, _chain: tuple[Path, ...] = ()) -> dict[str, Any]:
    """Read a config file and everything it extends into one merged mapping (not yet validated)."""
    path = Path(path).resolve()
    if path in _chain:
        cycle = " -> ".join(str(p) for p in (*_chain, path))
        raise ConfigError(f"'extends' forms a cycle: {cycle}")
    document = _read_yaml_mapping(path)
    bases = document.pop("extends", [])
    if isinstance(bases, str):
        bases = [bases]
    if not isinstance(bases, list):
        raise ConfigError(f"{path}: 'extends' must be a file path or a list of file paths")
    merged: dict[str, Any] = {}
    for base in bases:
        merged = deep_merge(merged, load_raw(_resolve_base(base, path), (*_chain, path)))
    return deep_merge(merged, document)


def parse_override(assignment: str) -> tuple[list[str], Any]:
    """Parse ``key.path=value`` (value in YAML syntax) as given to ``--set``."""
    key, sep, value_text = assignment.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"override {assignment!r} must look like key.path=value")
    try:
        value = yaml.safe_load(value_text) if value_text.strip() else None
    except yaml.YAMLError:
        value = value_text
    return key.strip().split("."), value


def _list_index(node: list, key: str, assignment: str) -> int:
    if not re.fullmatch(r"-?[0-9]+", key) or not -len(node) <= int(key) < len(node):
        raise ConfigError(
            f"override {assignment!r}: {key!r} is not an item of a list of {len(node)} "
            f"(use an index from 0 to {len(node) - 1})"
        )
    return int(key)


def apply_overrides(raw: dict[str, Any], assignments: Iterable[str]) -> dict[str, Any]:
    """Apply ``key.path=value`` overrides; a number in the path picks an item of a list
    (``scene.objects.0.medium=ice``), so list items can be changed without repeating the list."""
    result = copy.deepcopy(raw)
    for assignment in assignments:
        keys, value = parse_override(assignment)
        node: Any = result
        for k in keys[:-1]:
            if isinstance(node, list):
                node = node[_list_index(node, k, assignment)]
                continue
            if not isinstance(node.get(k), (dict, list)):
                node[k] = {}
            node = node[k]
        if isinstance(node, list):
            node[_list_index(node, keys[-1], assignment)] = value
        elif isinstance(node, dict):
            node[keys[-1]] = value
        else:
            raise ConfigError(f"override {assignment!r}: {'.'.join(keys[:-1])} is a value, not a mapping or a list")
    return result


def format_key_path(parts) -> str:
    """``render.initial_beam_radius``; odd keys (spaces, dots, empty) are quoted so they stay visible."""
    shown = [str(p) if isinstance(p, int) or re.fullmatch(r"[A-Za-z0-9_-]+", str(p)) else repr(str(p)) for p in parts]
    return ".".join(shown) or "(top level)"


def _known_keys(loc: tuple) -> list[str]:
    """The keys the schema allows at ``loc`` (a pydantic error location), for "did you mean": the
    children of ``loc`` in the config reference, whose ``<id>`` and ``<i>`` match any name and index."""
    from pipeline.reference import entries, key_pattern

    parent = ".".join(str(part) for part in loc)
    known = []
    for entry in entries():
        head, _, child = entry.key.rpartition(".")
        if child not in ("<id>", "<i>") and re.fullmatch(key_pattern(head), parent):
            known.append(child)
    return known


def format_validation_error(error: ValidationError, source: str) -> str:
    lines = [f"{source}: {error.error_count()} problem(s) in the config:"]
    for item in error.errors(include_url=False):
        key_path = format_key_path(item["loc"])
        if item["type"] == "extra_forbidden":
            close = difflib.get_close_matches(str(item["loc"][-1]), _known_keys(item["loc"][:-1]), n=1)
            hint = f"did you mean '{close[0]}'?" if close else "remove it or check its spelling"
            lines.append(f"  {key_path}: unknown key (value {item['input']!r}); {hint}")
            continue
        if item["type"] == "missing":
            lines.append(f"  {key_path}: required key is missing")
            continue
        value = item.get("input")
        value_text = repr(value) if not isinstance(value, dict) else "a mapping"
        if len(value_text) > 80:
            value_text = value_text[:77] + "..."
        # One line per problem, whatever the message quotes (a name with a newline in it, say).
        message = item["msg"].removeprefix("Value error, ").replace("\n", "\\n")
        lines.append(f"  {key_path}: value {value_text} is not allowed: {message}")
    return "\n".join(lines)


def validate(raw: Mapping[str, Any], source: str = "config"):
    from pipeline.schema import Config

    try:
        return Config.model_validate(dict(raw))
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, source)) from None


def load_config(path: str | Path, overrides: Iterable[str] = ()):
    """Load, merge, override and validate a config file. The run name defaults to the file stem."""
    path = Path(path)
    raw = apply_overrides(load_raw(path), overrides)
    raw.setdefault("name", path.stem)
    _resolve_relative_paths(raw, path.resolve().parent)
    config = validate(raw, source=str(path))
    check_input_files(config, source=str(path))
    return config


def _resolve_relative_paths(raw: dict[str, Any], folder: Path) -> None:
    """Mesh paths relative to the config file's folder become absolute, so a run does not depend on
    the working directory. A path the operating system cannot name (a NUL byte) stays as written, for
    validation to refuse naming its key."""
    scene = raw.get("scene")
    objects = scene.get("objects") if isinstance(scene, dict) else None
    for obj in objects if isinstance(objects, list) else []:
        if isinstance(obj, dict) and isinstance(obj.get("path"), str) and obj["path"] and "\0" not in obj["path"]:
            if not Path(obj["path"]).expanduser().is_absolute():
                obj["path"] = str((folder / obj["path"]).resolve())


def check_input_files(config, source: str = "config") -> None:
    """Refuse a config whose input files are missing or unreadable, naming the key and the file."""
    from geometry.meshio import read_mesh

    problems = []
    for i, obj in enumerate(config.scene.objects):
        if obj.shape != "ply" or not obj.path:
            continue
        try:
            read_mesh(Path(obj.path).expanduser())
        except FileNotFoundError as exc:
            problems.append(f"  scene.objects.{i}.path: {exc} (a relative path is read from the config file's folder)")
        except (OSError, ValueError) as exc:
            problems.append(f"  scene.objects.{i}.path: {exc}")
    if problems:
        raise ConfigError(f"{source}: {len(problems)} problem(s) with input files:\n" + "\n".join(problems))


def subtree(config_dump: Mapping[str, Any], dotted_key: str) -> Any:
    node: Any = config_dump
    for part in dotted_key.split("."):
        node = node[part]
    return node


def config_hash(config, keys: Iterable[str]) -> str:
    """SHA-256 of the canonical JSON of the named config subtrees: what a stage depends on."""
    dump = config.model_dump(mode="json")
    selected = {key: subtree(dump, key) for key in sorted(set(keys))}
    canonical = json.dumps(selected, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()

"""The config reference, generated from the pydantic schema: every key with its type, default, unit
and description, grouped by the stage section it belongs to.

``python -m pipeline docs`` writes ``docs/config-reference.md``; ``python -m pipeline validate
--explain KEY`` prints one entry. A test regenerates the page and fails when the file is stale.
Units come from the ``[unit]`` that every field description carries.
"""

from __future__ import annotations

import functools
import json
import re
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from common.paths import PROJECT_ROOT

REFERENCE_PATH = PROJECT_ROOT / "docs" / "config-reference.md"
UNIT = re.compile(r"\s*\[([^\[\]]+)\]")


@dataclass(frozen=True)
class KeyEntry:
    """One config key: dotted path (``<id>`` for a mapping key, ``<i>`` for a list item)."""

    key: str
    type: str
    default: str
    unit: str
    description: str


def _type_name(annotation: Any) -> str:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_name(a) for a in args)
    if origin is typing.Literal:
        return " | ".join(json.dumps(a) for a in args)
    if origin in (list, tuple, dict):
        inner = ", ".join(_type_name(a) for a in args if a is not Ellipsis)
        return f"{origin.__name__}[{inner}]"
    if annotation is type(None):
        return "null"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "mapping"
    return getattr(annotation, "__name__", str(annotation))


def _default(field: FieldInfo) -> str:
    if field.default_factory is not None:
        value = field.default_factory()  # type: ignore[call-arg]
    elif field.default is PydanticUndefined:
        return "required"
    else:
        value = field.default
    if isinstance(value, BaseModel):
        return "(see its keys)"
    if isinstance(value, (list, dict)) and value and isinstance(next(iter(value)), BaseModel):
        return "(see its keys)"
    if isinstance(value, dict) and value and any(isinstance(v, BaseModel) for v in value.values()):
        return json.dumps({k: v.model_dump(mode="json", exclude_defaults=True) for k, v in value.items()})
    return json.dumps(value, default=str)


def _nested_models(annotation: Any) -> list[tuple[str, type[BaseModel]]]:
    """The models a field holds: itself, list items (``<i>``) or mapping values (``<id>``)."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [("", annotation)]
    if origin in (typing.Union, types.UnionType, typing.Annotated):
        return [m for a in args for m in _nested_models(a)]
    if origin is list and args:
        return [(".<i>" + suffix, model) for suffix, model in _nested_models(args[0])]
    if origin is dict and len(args) == 2:
        return [(".<id>" + suffix, model) for suffix, model in _nested_models(args[1])]
    return []


@functools.cache
def entries(model: type[BaseModel] | None = None, prefix: str = "") -> tuple[KeyEntry, ...]:
    """Every key of ``model`` (the whole config by default), depth first in declaration order."""
    if model is None:
        from pipeline.schema import Config

        model = Config
    out = []
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        text = field.description or ""
        units = UNIT.findall(text)
        description = UNIT.sub("", text).strip()
        out.append(
            KeyEntry(key, _type_name(field.annotation), _default(field), units[-1] if units else "", description)
        )
        for suffix, nested in _nested_models(field.annotation):
            out.extend(entries(nested, f"{key}{suffix}."))
    return tuple(out)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown() -> str:
    """The whole reference page."""
    from pipeline.schema import Config

    all_entries = entries()
    top = [e for e in all_entries if "." not in e.key]
    lines = [
        "# Config reference",
        "",
        "Generated from the schema (`pipeline/schema/`) by `python -m pipeline docs`; do not edit by hand.",
        "`python -m pipeline validate --explain KEY` prints one entry. Keys are dotted paths as in",
        "`--set key=value`: `<id>` stands for a name you choose (a medium), `<i>` for a list index.",
        "Lengths are metres; time is optical path length in metres (seconds = OPL / 299 792 458).",
        "",
        "## Top level",
        "",
        "| key | type | default | unit | description |",
        "|---|---|---|---|---|",
    ]
    sections = [e for e in top if _nested_models(Config.model_fields[e.key].annotation)]
    lines += [
        f"| `{e.key}` | {_cell(e.type)} | `{_cell(e.default)}` | {e.unit} | {_cell(e.description)} |" for e in top
    ]
    for section in sections:
        lines += ["", f"## `{section.key}`", "", section.description, ""]
        lines += ["| key | type | default | unit | description |", "|---|---|---|---|---|"]
        for e in all_entries:
            if e.key.startswith(section.key + "."):
                lines.append(
                    f"| `{e.key}` | {_cell(e.type)} | `{_cell(e.default)}` | {e.unit} | {_cell(e.description)} |"
                )
    return "\n".join(lines) + "\n"


def key_pattern(key: str) -> str:
    """A regular expression for a reference key: ``<id>`` matches any name, ``<i>`` any index."""
    return re.escape(key).replace(re.escape("<id>"), r"[^.]+").replace(re.escape("<i>"), r"\d+")


def explain(key: str) -> str:
    """One key's entry, or an error that lists the closest keys."""
    import difflib

    by_key = {e.key: e for e in entries()}
    found = by_key.get(key)
    for pattern_key, entry in by_key.items():  # a medium id in place of <id>, an index in place of <i>
        if found is not None:
            break
        if re.fullmatch(key_pattern(pattern_key), key):
            found = entry
    if found is None:
        close = difflib.get_close_matches(key, list(by_key), n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise KeyError(f"no config key '{key}'{hint}")
    unit = f" [{found.unit}]" if found.unit else ""
    return f"{found.key}: {found.type}{unit}, default {found.default}\n  {found.description}\n"


def write(path: Path = REFERENCE_PATH) -> Path:
    from common.atomic import write_text_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(path, markdown())

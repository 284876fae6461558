"""Fuzz the config loader with generated YAML documents: every invalid config is refused with a
ConfigError that names a key, and nothing else escapes (no crash, no traceback for users).

Two kinds of documents: arbitrary keys and values at the top level, and a complete valid config
with one to three hostile edits deep inside it (NaN, infinities, huge or negative numbers, wrong
types, deleted keys, unknown keys, whole sections replaced), whose errors must name the edited key.
"""

from __future__ import annotations

import copy
import math
import re

import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from pipeline.config import ConfigError, format_key_path, load_config, validate

KNOWN_KEYS = ["name", "seed", "threads", "runs_dir", "geometry", "scene", "reference", "render", "composite"]
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8,
)
documents = st.dictionaries(st.sampled_from(KNOWN_KEYS) | st.text(min_size=1, max_size=10), values, max_size=6)


@settings(
    max_examples=500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(document=documents)
def test_generated_configs_are_accepted_or_refused_with_a_key(tmp_path_factory, document):
    path = tmp_path_factory.mktemp("fuzz") / "point.yaml"
    path.write_text(yaml.safe_dump(document, allow_unicode=True), encoding="utf-8")
    try:
        cfg = load_config(path)
    except ConfigError as exc:
        message = str(exc)
        # Each problem line starts with the key path it is about.
        problem_lines = [line for line in message.splitlines()[1:] if line.strip()]
        if not problem_lines:  # loader-level errors are one line naming the key, e.g. 'extends'
            assert re.search(r"'[^']+'", message), message
        for line in problem_lines:
            assert re.match(r"^  \S.*?: (unknown key|value |required key)", line), message
    else:
        assert cfg.name


@settings(max_examples=200, deadline=None)
@given(text=st.text(max_size=200))
def test_arbitrary_text_never_escapes_as_anything_but_config_error(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("fuzz") / "raw.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        load_config(path)
    except ConfigError:
        pass


# A small valid run: a box of medium, every section present. Its full dump lists every key.
BASE = {
    "name": "fuzzed",
    "seed": 3,
    "threads": 2,
    "scene": {
        "media": {"snow": {"coefficients": {"sigma_s": [3.0, 2.5, 2.0], "sigma_a": [0.3, 0.1, 0.05], "g": 0.2}}},
        "objects": [{"name": "block", "shape": "box", "medium": "snow", "center": [0, 0, -0.5], "size": [2, 2, 1]}],
        "camera": {"placement": "look_at", "origin": [0, -4, 3], "target": [0, 0, -0.3], "width": 24, "height": 16},
        "area_lights": [{"center": [0, 0, 2]}],
        "pulse_lights": [{"kind": "spot"}],
        "film": {"temporal_bins": 12, "window": "manual", "start_opl": 3.0, "bin_width_opl": 0.1},
    },
    "render": {
        "iterations": 12,
        "checkpoint_every_iterations": 4,
        "checkpoint_every_s": 60.0,
        "time_budget_s": 100.0,
        "alpha": 0.8,
    },
}
FULL = validate(BASE).model_dump(mode="json")


def leaf_paths(node, prefix=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield from leaf_paths(value, (*prefix, key))
    elif isinstance(node, list) and node:
        for i, value in enumerate(node):
            yield from leaf_paths(value, (*prefix, i))
    else:
        yield prefix


LEAVES = sorted(leaf_paths(FULL), key=str)
hostile_values = st.one_of(
    st.sampled_from(
        [
            math.nan,
            math.inf,
            -math.inf,
            -1,
            0,
            -1e308,
            1e308,
            10**30,
            -(10**30),
            2**63,
            "",
            "x" * 300,
            None,
            True,
            False,
            [],
            {},
            [0] * 5,
            {"a": 1},
            [math.nan] * 3,
            "1e400",
            "-.inf",
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**20), 10**20),
    st.text(max_size=10),
)
edits = st.tuples(
    st.sampled_from(LEAVES),
    st.sampled_from(["replace", "replace", "delete", "unknown key", "parent"]),
    hostile_values,
    st.text(min_size=1, max_size=8),
)


def apply_edit(document: dict, path: tuple, op: str, value, key: str) -> tuple | None:
    """Apply one edit in place; return the key path it touched (None when an earlier edit removed it)."""
    if op == "parent" and len(path) > 1:
        path = path[:-1]
    node = document
    for part in path[:-1]:
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            return None
        if not isinstance(node, (dict, list)):
            return None
    last = path[-1]
    if (
        isinstance(node, dict)
        and last not in node
        or isinstance(node, list)
        and not (isinstance(last, int) and last < len(node))
    ):
        return None
    if op == "delete":
        del node[last]
    elif op == "unknown key":
        if not isinstance(node, dict) or key in node:
            return None
        node[key] = value
        return (*path[:-1], key)
    else:
        node[last] = value
    return path


@settings(
    max_examples=500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(chosen=st.lists(edits, min_size=1, max_size=3))
def test_hostile_edits_deep_in_a_valid_config_are_refused_naming_the_key(tmp_path_factory, chosen):
    document = copy.deepcopy(FULL)
    touched = [t for t in (apply_edit(document, *edit) for edit in chosen) if t is not None]
    path = tmp_path_factory.mktemp("fuzz") / "point.yaml"
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml halves the time of each example
    path.write_text(yaml.dump(document, Dumper=dumper, allow_unicode=True), encoding="utf-8")
    try:
        cfg = load_config(path)
    except ConfigError as exc:
        event("refused")
        message = str(exc)
        lines = [line for line in message.splitlines()[1:] if line.strip()]
        assert lines, message
        # A problem is about an edited key, something inside it, or the section that holds it.
        named = {format_key_path(t[:n]) for t in touched for n in range(1, len(t) + 1)}
        for line in lines:
            assert re.match(r"^  \S.*?: (unknown key|value |required key)", line), message
            assert any(line.startswith(f"  {p}:") or line.startswith(f"  {p}.") for p in named), (touched, message)
    else:
        event("accepted")

        def floats(node):
            if isinstance(node, dict):
                return [x for v in node.values() for x in floats(v)]
            if isinstance(node, list):
                return [x for v in node for x in floats(v)]
            return [node] if isinstance(node, float) else []

        assert all(math.isfinite(x) for x in floats(cfg.model_dump(mode="json")))  # NaN and inf never pass

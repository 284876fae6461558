"""Fuzz the config loader with generated YAML documents: every invalid config is refused with a
ConfigError that names a key, and nothing else escapes (no crash, no traceback for users)."""
from __future__ import annotations

import re

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.config import ConfigError, load_config

KNOWN_KEYS = ["name", "seed", "threads", "runs_dir", "geometry", "scene", "reference", "render", "composite"]
scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3), max_leaves=8)
documents = st.dictionaries(st.sampled_from(KNOWN_KEYS) | st.text(min_size=1, max_size=10), values, max_size=6)


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
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

"""docs/config-reference.md is generated from the schema: complete (every key), current (regenerating
it changes nothing) and explained per key by ``pipeline validate --explain``."""

from __future__ import annotations

import re
import subprocess
import sys

from pipeline.config import load_config
from pipeline.reference import REFERENCE_PATH, entries, explain, markdown


def dotted_keys(node, prefix=""):
    """Every key of a config dump, with mapping ids and list indices written as <id> and <i>."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield f"{prefix}{key}"
            yield from dotted_keys(value, f"{prefix}{key}.")
    elif isinstance(node, list):
        for value in node:
            yield from dotted_keys(value, f"{prefix}<i>.")


def test_the_reference_file_is_current():
    assert REFERENCE_PATH.read_text(encoding="utf-8") == markdown(), (
        "docs/config-reference.md is stale: run `python -m pipeline docs`"
    )


def test_the_reference_lists_every_key_of_a_full_config():
    documented = {e.key for e in entries()}
    dump = load_config("configs/demo.yaml").model_dump(mode="json")
    used = {re.sub(r"^scene\.media\.[^.]+", "scene.media.<id>", k) for k in dotted_keys(dump)}
    assert {k for k in used if not k.endswith("<id>")} - documented == set()
    text = REFERENCE_PATH.read_text(encoding="utf-8")
    assert all(f"`{key}`" in text for key in documented)


def test_every_key_has_a_description_and_a_unit_where_it_is_a_number():
    for entry in entries():
        assert entry.description, entry.key
        if entry.type in ("int", "float") or entry.type.startswith(("float |", "int |")):
            assert entry.unit, f"{entry.key} has no [unit] in its description"


def test_explain_prints_one_key_and_suggests_on_a_typo():
    text = explain("scene.objects.0.medium")
    assert text.startswith("scene.objects.<i>.medium: str | null")
    assert "sigma" in explain("scene.media.ice.coefficients.sigma_s")
    run = subprocess.run(
        [sys.executable, "-m", "pipeline", "validate", "--explain", "render.iteratons"], capture_output=True, text=True
    )
    assert run.returncode == 2 and "did you mean render.iterations" in run.stderr

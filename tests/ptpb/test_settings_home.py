"""One home per render setting (issue 50): the core declares each settings key and its default once
(RenderSettings and for_each_setting in render/core/include/ptpb/settings.hpp, read through
render._core.render_settings_defaults); the render section of the config (PTPBConfig) describes the same keys
and takes the same defaults. A key on one side only, or a default that differs, fails here."""

from __future__ import annotations

import pytest

from pipeline.schema.ptpb import CORE_DEFAULTS, PTPBConfig
from render import _core
from render.ptpb.settings import API_ONLY_KEYS, RESOLVED_KEYS, SCENE_KEYS, resolve_settings
from tests.ptpb.test_core_defaults import scene

# The render section's keys that are core settings: all but those that go into the core's scene dict.
SCHEMA_KEYS = set(PTPBConfig.model_fields) - set(SCENE_KEYS)
CORE_KEYS = set(_core.render_settings_defaults())
AS_GIVEN = sorted(SCHEMA_KEYS - set(RESOLVED_KEYS))


def test_every_core_key_has_one_home():
    homeless = CORE_KEYS - SCHEMA_KEYS - set(RESOLVED_KEYS) - set(API_ONLY_KEYS)
    assert not homeless, (
        f"the core parses {sorted(homeless)}, which the render section does not declare: add a Field in "
        "pipeline/schema/ptpb.py (default CORE_DEFAULTS[key]), or list the key in render/ptpb/settings.py "
        "(RESOLVED_KEYS when resolve_settings computes it, API_ONLY_KEYS when no config sets it)"
    )
    assert not (set(API_ONLY_KEYS) & SCHEMA_KEYS), "a key the config sets is listed as API-only"
    assert set(SCENE_KEYS) <= set(PTPBConfig.model_fields) and not set(SCENE_KEYS) & CORE_KEYS


def test_every_schema_key_reaches_the_core():
    unknown = (SCHEMA_KEYS | set(RESOLVED_KEYS) | set(API_ONLY_KEYS)) - CORE_KEYS
    assert not unknown, (
        f"{sorted(unknown)} are declared in Python but the core does not parse them: add each to RenderSettings "
        "and for_each_setting (render/core/include/ptpb/settings.hpp), or remove it"
    )


@pytest.mark.parametrize("key", AS_GIVEN)
def test_the_schema_default_is_the_cores(key):
    assert PTPBConfig.model_fields[key].default == CORE_DEFAULTS[key]
    assert type(PTPBConfig.model_fields[key].default) is type(CORE_DEFAULTS[key])


def test_resolve_settings_hands_every_key_to_the_core():
    core = resolve_settings(scene("bins"), PTPBConfig())
    assert set(core) == SCHEMA_KEYS | set(RESOLVED_KEYS)
    assert all(core[key] == CORE_DEFAULTS[key] for key in AS_GIVEN)


def test_the_core_parses_its_defaults_as_they_are():
    # The defaults dict, given back as a settings dict, renders exactly as the keys left out.
    core_scene = scene("bins")
    given = {**CORE_DEFAULTS, "iterations": 2, "light_paths_per_iteration": 200, "snapshot_every": 1}
    left_out = {"iterations": 2, "light_paths_per_iteration": 200, "snapshot_every": 1, "initial_beam_radius": 0.01}
    a, b = _core.ptpb_render(core_scene, given), _core.ptpb_render(core_scene, left_out)
    assert a["frames"].tobytes() == b["frames"].tobytes()
    assert a["stats"]["iterations"] == 2

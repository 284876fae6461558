"""One home per render setting (issue 50): the core declares each setting once (RenderSettings and
for_each_setting in render/core/include/ptpb/settings.hpp, read through render._core.render_settings_spec), with
its key, default, bounds, choices and description; the render section of the config (PTPBConfig) is built from
that declaration. A key on one side only, or a default, kind, bound or description that differs, fails here,
and so does a value past a bound that the schema lets through."""

from __future__ import annotations

import math
import typing

import pytest
from pydantic import ValidationError

from pipeline.config import ConfigError, validate
from pipeline.schema.ptpb import CORE_DEFAULTS, CORE_SPEC, OWN_KEY_AFTER, PTPBConfig
from render import _core
from render.ptpb.settings import RESOLVED_KEYS, SCENE_KEYS, resolve_settings
from tests.render.ptpb.test_core_defaults import scene

SPEC = {spec["key"]: spec for spec in _core.render_settings_spec()}
# The render section's keys that are core settings: all but those that go into the core's scene dict.
SCHEMA_KEYS = set(PTPBConfig.model_fields) - set(SCENE_KEYS)
CONFIG_KEYS = {key for key, spec in SPEC.items() if spec["config"]}
API_ONLY_KEYS = set(SPEC) - CONFIG_KEYS
# The settings the schema takes from the core as they are: every config key but those with units of their own.
AS_GIVEN = sorted(CONFIG_KEYS - set(RESOLVED_KEYS))
BOUNDS = [(key, name) for key in AS_GIVEN for name in ("ge", "gt", "le", "lt") if SPEC[key][name] is not None]
PYTHON_TYPES = {"int": int, "float": float, "bool": bool, "optional": float | None}


def test_every_core_key_has_one_home():
    homeless = CONFIG_KEYS - SCHEMA_KEYS
    assert not homeless, f"the core declares {sorted(homeless)} for configs, but the render section lacks them"
    assert not (API_ONLY_KEYS & SCHEMA_KEYS), "a key the core declares API-only (only_from_the_api) is a config key"
    assert set(SCENE_KEYS) <= set(PTPBConfig.model_fields) and not set(SCENE_KEYS) & set(SPEC)
    assert set(RESOLVED_KEYS) <= set(SPEC), "resolve_settings computes a key the core does not parse"


def test_every_schema_key_reaches_the_core():
    unknown = SCHEMA_KEYS - set(SPEC)
    assert not unknown, (
        f"{sorted(unknown)} are declared in Python but the core does not parse them: declare each in "
        "RenderSettings and for_each_setting (render/core/include/ptpb/settings.hpp), or remove it"
    )


def test_the_schema_keeps_the_cores_order():
    # Dumps, sweep point files and the config reference list the keys in this order.
    schema_order = [key for key in PTPBConfig.model_fields if key not in OWN_KEY_AFTER]
    assert schema_order == [spec["key"] for spec in CORE_SPEC if spec["config"]]
    keys = list(PTPBConfig.model_fields)
    for own_key, after in OWN_KEY_AFTER.items():
        assert keys.index(own_key) == keys.index(after) + 1


def test_the_spec_is_the_cores_own():
    # The schema reads the list once at import; the core gives the same list on every call.
    assert CORE_SPEC == list(SPEC.values())
    assert CORE_DEFAULTS == {key: spec["default"] for key, spec in SPEC.items()}


@pytest.mark.parametrize("key", AS_GIVEN)
def test_the_schema_field_is_the_cores_declaration(key):
    spec, field = SPEC[key], PTPBConfig.model_fields[key]
    assert field.default == spec["default"] and type(field.default) is type(spec["default"])
    assert field.description == spec["description"]
    if spec["kind"] == "enum":
        assert typing.get_origin(field.annotation) is typing.Literal
        assert list(typing.get_args(field.annotation)) == spec["choices"]
        assert spec["default"] in spec["choices"]
    else:
        assert field.annotation == PYTHON_TYPES[spec["kind"]] and spec["choices"] is None
    bounds = {name: getattr(m, name) for m in field.metadata for name in ("ge", "gt", "le", "lt") if hasattr(m, name)}
    assert bounds == {name: spec[name] for name in ("ge", "gt", "le", "lt") if spec[name] is not None}


def test_the_core_kinds_match_its_defaults():
    for key, spec in SPEC.items():
        default = spec["default"]
        if spec["kind"] in ("int", "bool"):
            assert type(default) is PYTHON_TYPES[spec["kind"]], key
        elif spec["kind"] == "float":
            assert isinstance(default, float), key
        elif spec["kind"] == "optional":
            assert default is None or isinstance(default, float), key
        assert spec["description"].rstrip(".").endswith("]"), f"{key}'s description has no [unit] at its end"


def past(spec: dict, name: str) -> float:
    """The nearest value that the bound ``name`` of ``spec`` refuses."""
    bound = spec[name]
    if name in ("gt", "lt"):
        return bound
    step = 1 if spec["kind"] == "int" else None
    if name == "ge":
        return bound - step if step else math.nextafter(bound, -math.inf)
    return bound + step if step else math.nextafter(bound, math.inf)


@pytest.mark.parametrize("key, name", BOUNDS, ids=[f"{k}-{n}" for k, n in BOUNDS])
def test_a_value_past_a_core_bound_is_refused_naming_the_key(key, name):
    spec = SPEC[key]
    with pytest.raises(ValidationError) as refused:
        PTPBConfig.model_validate({key: past(spec, name)})
    (error,) = refused.value.errors()
    assert error["loc"] == (key,)
    if name in ("ge", "le"):  # the bound itself is allowed
        assert getattr(PTPBConfig.model_validate({key: spec[name]}), key) == spec[name]


def test_a_config_names_the_key_past_a_bound():
    with pytest.raises(ConfigError) as refused:
        validate({"name": "bounds", "render": {"path_splits": SPEC["path_splits"]["le"] + 1}})
    assert "render.path_splits: value 9 is not allowed: Input should be less than or equal to 8" in str(refused.value)
    with pytest.raises(ConfigError, match=r"render\.surface_normal_cos: value 0 is not allowed"):
        validate({"name": "bounds", "render": {"surface_normal_cos": SPEC["surface_normal_cos"]["gt"]}})


@pytest.mark.parametrize("key", [key for key in AS_GIVEN if SPEC[key]["kind"] == "enum"])
def test_an_enum_takes_the_cores_choices_only(key):
    for choice in SPEC[key]["choices"]:
        assert getattr(PTPBConfig.model_validate({key: choice}), key) == choice
    with pytest.raises(ValidationError, match=key):
        PTPBConfig.model_validate({key: "none of them"})


def test_an_api_only_key_is_no_config_key():
    with pytest.raises(ConfigError, match=r"render\.jitter: unknown key"):
        validate({"name": "api_only", "render": {"jitter": False}})


def test_resolve_settings_hands_every_key_to_the_core():
    core = resolve_settings(scene("bins"), PTPBConfig())
    assert set(core) == SCHEMA_KEYS | set(RESOLVED_KEYS)
    assert all(core[key] == CORE_DEFAULTS[key] for key in AS_GIVEN)


def test_the_core_parses_its_defaults_as_they_are():
    # The defaults, given back as a settings dict, render exactly as the keys left out.
    core_scene = scene("bins")
    given = {**CORE_DEFAULTS, "iterations": 2, "light_paths_per_iteration": 200, "snapshot_every": 1}
    left_out = {"iterations": 2, "light_paths_per_iteration": 200, "snapshot_every": 1, "initial_beam_radius": 0.01}
    a, b = _core.ptpb_render(core_scene, given), _core.ptpb_render(core_scene, left_out)
    assert a["frames"].tobytes() == b["frames"].tobytes()
    assert a["stats"]["iterations"] == 2

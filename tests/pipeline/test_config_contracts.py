"""Keys with one home: preset names resolved at validate, and the render keys that live elsewhere
(seed, threads, path depth) refused under render: rather than silently replaced."""

from __future__ import annotations

import pytest

from common.paths import optics_preset_names
from pipeline.config import ConfigError, load_config

DEMO = "configs/demo.yaml"


def test_a_misspelled_preset_is_refused_at_validate_with_a_suggestion():
    with pytest.raises(ConfigError) as refused:
        load_config(DEMO, ["scene.media.snow.preset=fresh_snw"])
    text = str(refused.value)
    assert "scene.media.snow.preset" in text
    assert "unknown optical preset 'fresh_snw'" in text and "did you mean 'fresh_snow'?" in text
    for name in optics_preset_names():
        assert name in text  # every available preset is listed


def test_every_preset_on_disk_validates():
    assert {"penitente_firn", "bubbly_ice", "thesis_set_6"} <= set(optics_preset_names())
    for name in optics_preset_names():
        assert load_config(DEMO, [f"scene.media.snow.preset={name}"]).scene.media["snow"].preset == name


@pytest.mark.parametrize(
    ("key", "home"),
    [("seed", "seed"), ("threads", "threads"), ("max_depth", "scene.max_depth")],
)
def test_render_keys_with_another_home_are_refused(key, home):
    with pytest.raises(ConfigError, match=rf"render\.{key} cannot be set in a pipeline config: set `{home}`"):
        load_config(DEMO, [f"render.{key}=3"])


def test_the_render_stage_gets_the_root_seed_threads_and_the_scene_depth():
    config = load_config(DEMO, ["seed=11", "threads=1", "scene.max_depth=-1", "render.rr_depth=12"])
    settings = config.render_settings()
    assert (settings.seed, settings.threads, settings.max_depth, settings.rr_depth) == (11, 1, -1, 12)
    # A dump leaves the borrowed keys out, so it validates again (sweeps write point configs this way).
    dump = config.model_dump(mode="json")
    assert not {"seed", "threads", "max_depth"} & set(dump["render"])
    assert type(config).model_validate(dump).render_settings() == settings


def test_the_video_title_comes_from_the_config():
    from pipeline.stages import run_title

    assert run_title(load_config(DEMO)) == "Penitentes at 30.1°S, 19 Dec, sun at 07:30 solar time: light in flight"
    northern = load_config(DEMO, ["geometry.latitude=28.0", "scene.sun.solar_time_h=15.5", "geometry.days=1"])
    assert run_title(northern) == "Penitentes at 28.0°N, 1 Oct, sun at 15:30 solar time: light in flight"


def test_a_reference_film_that_does_not_tile_ours_is_refused():
    with pytest.raises(ConfigError) as refused:
        load_config(DEMO, ["reference.downsample=3"])  # the demo's 320 x 240 is no multiple of 3
    text = str(refused.value)
    assert "reference.downsample = 3 must divide scene.camera.width (320)" in text
    assert load_config(DEMO, ["reference.downsample=4"]).reference.downsample == 4

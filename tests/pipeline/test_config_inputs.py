"""Inputs checked when a config is loaded (``pipeline validate``): mesh files exist and can be read,
relative paths are read from the config file's folder, unknown keys get a suggestion, and ``--set``
reaches list items."""

from __future__ import annotations

import pytest
import yaml

from geometry.meshio import write_ply
from pipeline.config import ConfigError, load_config
from render.scene.shapes import box_mesh


def write_config(folder, mesh_path: str, **extra) -> object:
    folder.mkdir(parents=True, exist_ok=True)
    document = {
        "scene": {
            "media": {"snow": {"preset": "fresh_snow"}},
            "objects": [{"name": "block", "shape": "ply", "path": mesh_path, "medium": "snow"}],
        },
        **extra,
    }
    path = folder / "run.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_a_missing_mesh_file_is_refused_at_validate_naming_the_key(tmp_path):
    config = write_config(tmp_path, "no_such_mesh.ply")
    with pytest.raises(ConfigError, match=r"scene\.objects\.0\.path: .*no_such_mesh\.ply: mesh file not found"):
        load_config(config)


def test_a_path_with_a_nul_byte_is_refused_naming_the_key(tmp_path):
    # Resolving it against the config's folder raised "embedded null byte" from pathlib before any key was named
    # (found by test_config_fuzz); it now reaches the input check as written.
    with pytest.raises(ConfigError, match=r"scene\.objects\.0\.path: .*mesh file not found"):
        load_config(write_config(tmp_path, "a\x00b.ply"))


def test_an_unreadable_mesh_file_is_refused_at_validate(tmp_path):
    (tmp_path / "broken.obj").write_text("not a mesh at all\n")
    with pytest.raises(ConfigError, match=r"scene\.objects\.0\.path: .*broken\.obj: the mesh is empty"):
        load_config(write_config(tmp_path, "broken.obj"))


def test_a_relative_mesh_path_resolves_against_the_config_files_folder(tmp_path, monkeypatch):
    write_ply(tmp_path / "meshes" / "box.ply", *box_mesh())
    config_path = write_config(tmp_path / "configs" / "mine", "../../meshes/box.ply")
    monkeypatch.chdir(tmp_path / "configs")  # somewhere else: the working directory must not matter
    config = load_config(config_path.relative_to(tmp_path / "configs"))
    assert config.scene.objects[0].path == str((tmp_path / "meshes" / "box.ply").resolve())


def test_a_misspelled_key_gets_a_suggestion(tmp_path):
    write_ply(tmp_path / "box.ply", *box_mesh())
    config = write_config(tmp_path, "box.ply", render={"iteratons": 4})
    with pytest.raises(ConfigError) as refused:
        load_config(config, ["scene.camera.widht=64", "scene.objects.0.medum=snow", "sed=3"])
    text = str(refused.value)
    assert "render.iteratons: unknown key (value 4); did you mean 'iterations'?" in text
    assert "scene.camera.widht: unknown key (value 64); did you mean 'width'?" in text
    assert "scene.objects.0.medum: unknown key (value 'snow'); did you mean 'medium'?" in text
    assert "sed: unknown key (value 3); did you mean 'seed'?" in text


def test_set_reaches_list_items():
    config = load_config("configs/demo.yaml", ["scene.objects.1.margin=3.5", "scene.objects.0.medium=snow"])
    assert config.scene.objects[1].margin == 3.5 and config.scene.objects[1].name == "snowpack"
    assert config.scene.objects[0].name == "penitentes"  # the rest of the list is kept
    with pytest.raises(ConfigError, match=r"'7' is not an item of a list of 2 \(use an index from 0 to 1\)"):
        load_config("configs/demo.yaml", ["scene.objects.7.medium=snow"])


def test_a_misspelled_medium_name_gets_a_suggestion():
    with pytest.raises(ConfigError, match=r"names medium 'snwo'.*did you mean 'snow'\? defined: snow"):
        load_config("configs/demo.yaml", ["scene.objects.0.medium=snwo"])


def test_every_problem_stays_on_one_line_even_when_a_name_holds_a_newline():
    # Found by the config fuzz test: a medium name with a newline split its error over two lines.
    with pytest.raises(ConfigError) as refused:
        load_config("configs/demo.yaml", ['scene.pulse_lights=[{"kind": "spot", "medium": "a\\nb"}]'])
    problems = str(refused.value).splitlines()[1:]
    assert len(problems) == 1 and problems[0].startswith("  scene: value a mapping is not allowed: ")

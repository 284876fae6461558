"""Config loading: extends, overrides, and errors that name the file or key path."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.config import ConfigError, config_hash, deep_merge, load_config, load_raw


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_extends_merges_mappings_and_the_file_wins(tmp_path):
    write(tmp_path / "base.yaml", "seed: 5\nthreads: 2\n")
    cfg = load_config(write(tmp_path / "point.yaml", "extends: base.yaml\nthreads: 1\n"))
    assert (cfg.name, cfg.seed, cfg.threads) == ("point", 5, 1)


def test_extends_chain_and_list_order(tmp_path):
    write(tmp_path / "a.yaml", "seed: 1\nthreads: 1\n")
    write(tmp_path / "b.yaml", "extends: a.yaml\nseed: 2\n")
    write(tmp_path / "c.yaml", "threads: 3\n")
    cfg = load_config(write(tmp_path / "d.yaml", "extends: [b.yaml, c.yaml]\nname: sweep-point-1\n"))
    assert (cfg.name, cfg.seed, cfg.threads) == ("sweep-point-1", 2, 3)


def test_deep_merge_replaces_lists_and_merges_dicts():
    merged = deep_merge({"a": {"x": 1, "y": [1, 2]}, "b": 1}, {"a": {"y": [3]}, "c": 2})
    assert merged == {"a": {"x": 1, "y": [3]}, "b": 1, "c": 2}


def test_extends_cycle_is_reported(tmp_path):
    write(tmp_path / "a.yaml", "extends: b.yaml\n")
    write(tmp_path / "b.yaml", "extends: a.yaml\n")
    with pytest.raises(ConfigError, match="cycle"):
        load_raw(tmp_path / "a.yaml")


def test_missing_base_names_the_including_file(tmp_path):
    path = write(tmp_path / "a.yaml", "extends: nowhere.yaml\n")
    with pytest.raises(ConfigError, match=r"a\.yaml: extends 'nowhere\.yaml'"):
        load_config(path)


def test_missing_file_and_bad_yaml_are_clear(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "absent.yaml")
    path = write(tmp_path / "bad.yaml", "seed: [1, 2\nthreads: 1\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml at line \d+, column \d+: invalid YAML"):
        load_config(path)
    path = write(tmp_path / "list.yaml", "- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must be a YAML mapping"):
        load_config(path)


def test_unknown_key_names_its_path(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path / "x.yaml", "sed: 3\n"))
    assert "sed: unknown key" in str(info.value)


def test_wrong_type_names_key_value_and_rule(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path / "x.yaml", "threads: many\n"))
    message = str(info.value)
    assert "threads: value 'many' is not allowed" in message and "valid integer" in message


def test_out_of_range_names_the_bound(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path / "x.yaml", "seed: -1\n"))
    assert "seed: value -1 is not allowed: Input should be greater than or equal to 0" in str(info.value)


def test_overrides_apply_with_yaml_values(tmp_path):
    path = write(tmp_path / "x.yaml", "seed: 1\n")
    cfg = load_config(path, ["seed=9", "threads=2"])
    assert (cfg.seed, cfg.threads) == (9, 2)
    with pytest.raises(ConfigError, match="key.path=value"):
        load_config(path, ["seed"])


def test_config_hash_depends_only_on_the_named_subtrees(tmp_path):
    path = write(tmp_path / "x.yaml", "seed: 1\nthreads: 1\n")
    a = load_config(path)
    b = load_config(path, ["threads=2"])
    assert config_hash(a, ["seed"]) == config_hash(b, ["seed"])
    assert config_hash(a, ["threads"]) != config_hash(b, ["threads"])

"""The one YAML reader (``quad_uneven_env.config.read_yaml``): a key given twice is refused, naming it and its line."""

from __future__ import annotations

from pathlib import Path

import pytest

from quad_uneven_env.config import CONFIG_DIR, load_yaml_text, read_yaml

SUITE_WITH_TIME_LIMIT_TWICE = """\
name: tiny
goal_distance: 0.5
time_limit: 0.1
terrains:
  - kind: flat
    seeds: [0]
time_limit: 0.2
"""


def test_a_top_level_key_given_twice_is_refused_with_its_lines(tmp_path):
    path = tmp_path / "suite.yaml"
    path.write_text(SUITE_WITH_TIME_LIMIT_TWICE)
    with pytest.raises(ValueError) as err:
        read_yaml(path)
    msg = str(err.value)
    assert "suite.yaml" in msg and "'time_limit'" in msg
    assert "line 7" in msg and "first given at line 3" in msg


def test_a_nested_key_given_twice_is_refused():
    with pytest.raises(Exception, match=r"duplicate key 'seeds' \(first given at line 3\)"):
        load_yaml_text("terrains:\n  - kind: flat\n    seeds: [0]\n    seeds: [1]\n")


def test_merge_keys_may_be_overridden_and_distinct_keys_load():
    data = load_yaml_text("base: &b {friction: 1.0, mass: 2.0}\nentry:\n  <<: *b\n  friction: 0.5\n")
    assert data["entry"] == {"friction": 0.5, "mass": 2.0}


def test_yaml_stays_safe():
    with pytest.raises(Exception, match="could not determine a constructor"):
        load_yaml_text("x: !!python/object/apply:os.system ['true']\n")


def test_every_shipped_config_has_distinct_keys():
    files = sorted(Path(CONFIG_DIR).rglob("*.yaml"))
    assert len(files) > 10
    for path in files:
        assert isinstance(read_yaml(path), dict), path

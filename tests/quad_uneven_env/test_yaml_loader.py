"""The one YAML reader (``quad_uneven_env.config.read_yaml``): a key given twice is refused, naming it and its line."""

from __future__ import annotations

from pathlib import Path

import pytest

from quad_uneven_env import config
from quad_uneven_env.config import (
    CONFIG_DIR,
    MAX_ALIAS_VALUES,
    MAX_YAML_DEPTH,
    YamlLimitError,
    load_yaml_text,
    read_yaml,
)

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


def nested_aliases(levels: int) -> str:
    """A robot field whose value is 9 ** levels numbers, written in a few hundred bytes: each level's list holds
    the previous one 9 times (an anchor, then 8 aliases)."""
    value = "&a0 [" + ", ".join(["0.1"] * 9) + "]"
    for i in range(1, levels):
        value = f"&a{i} [{value}, " + ", ".join([f"*a{i - 1}"] * 8) + "]"
    return f"name: bomb\nfoot_radius: {value}\n"


def test_nested_aliases_are_refused_before_they_expand(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text(nested_aliases(9))  # 387 million numbers in 1 kB
    assert path.stat().st_size < 1000
    with pytest.raises(ValueError) as err:
        read_yaml(path)
    msg = str(err.value)
    assert "robot.yaml" in msg and "line 2" in msg and f"more than {MAX_ALIAS_VALUES} values" in msg
    assert len(msg) < 300


def test_aliases_within_the_cap_load_as_copies():
    text = "a: &a [1, 2, 3]\nb: *a\nc: [*a, *a]\n"
    assert load_yaml_text(text) == {"a": [1, 2, 3], "b": [1, 2, 3], "c": [[1, 2, 3], [1, 2, 3]]}
    many = "base: &b [" + ", ".join(["0"] * 99) + "]\nrows: [" + ", ".join(["*b"] * 100) + "]\n"  # 100 x 100
    assert len(load_yaml_text(many)["rows"]) == 100  # 100 aliases of 100 values: 10,000 repeated, the cap
    with pytest.raises(YamlLimitError, match="repeat more than"):
        load_yaml_text(many.replace("*b]", "*b, *b]"))


@pytest.mark.parametrize("text", ["a: &x [1, *x]\n", "a: &x {b: *x}\n", "a: &x [[[*x]]]\n"])
def test_a_value_containing_itself_is_refused(tmp_path, text):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"c\.yaml' is refused at line 1: the alias \*x lies inside its own anchor"):
        read_yaml(path)


def test_deep_nesting_is_refused_in_one_line(tmp_path):
    path = tmp_path / "deep.yaml"
    path.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ValueError, match=f"deeper than {MAX_YAML_DEPTH} levels"):
        read_yaml(path)
    assert load_yaml_text("a: " + "[" * (MAX_YAML_DEPTH - 1) + "]" * (MAX_YAML_DEPTH - 1) + "\n")


def test_a_file_beyond_the_size_cap_is_refused_unread(tmp_path, monkeypatch):
    monkeypatch.setattr(config, "MAX_YAML_BYTES", 1000, raising=False)
    path = tmp_path / "big.yaml"
    path.write_text("a: 1\n" + "# padding\n" * 200)
    with pytest.raises(ValueError, match=r"big\.yaml' is larger than"):
        read_yaml(path)

"""A huge value in a user's file or argument gives a short error: exit code 2, one ``error:`` line that names the
field and shows an excerpt of the value (``quad_uneven_env.fields.excerpt``), never the value in full.

Each case puts a list of 5,000 numbers (or a 100,000-character string, or 2,000 keys) where the field wants a
small value, in a suite, a robot description, a training or sweep config, or ``--env-kwargs``.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from agents.cli import main
from quad_uneven_env.config import CONFIG_DIR

BIG = list(range(5_000))
LONG = "x" * 100_000
MAX_MESSAGE = 400  # characters: the message's own words, the file's path and an excerpt of at most 120


def write(path: Path, raw: dict) -> Path:
    path.write_text(json.dumps(raw))  # YAML's flow style: quicker to write than yaml.safe_dump
    return path


def suite(tmp: Path, **changes) -> Path:
    raw = yaml.safe_load((CONFIG_DIR / "suites" / "smoke.yaml").read_text())
    return write(tmp / "suite.yaml", {**raw, **changes})


def robot(tmp: Path, **changes) -> Path:
    raw = yaml.safe_load((CONFIG_DIR / "robot" / "paper.yaml").read_text())
    return write(tmp / "robot.yaml", {**copy.deepcopy(raw), **changes})


def evaluate(tmp: Path, suite_arg: str, *extra: str) -> list[str]:
    return ["evaluate", "--policy", "zero", "--suite", suite_arg, "--out", str(tmp / "o"), *extra]


CASES: dict[str, tuple[Callable[[Path], list[str]], str]] = {
    "suite name": (lambda t: evaluate(t, str(suite(t, name=BIG))), "name must be"),
    "suite scale": (lambda t: evaluate(t, str(suite(t, scale=BIG))), "scale must be one of"),
    "suite terrains": (
        lambda t: evaluate(t, str(suite(t, terrains={str(i): i for i in range(2_000)}))),
        "terrains must be a non-empty list",
    ),
    "suite unknown keys": (
        lambda t: evaluate(t, str(suite(t, **{f"k{i}": 1 for i in range(2_000)}))),
        "unknown field(s)",
    ),
    "terrain parameter": (
        lambda t: evaluate(t, str(suite(t, terrains=[{"kind": "rough", "params": {"amplitude": LONG}, "seeds": [0]}]))),
        "terrains[0].params.amplitude must be",
    ),
    "terrain kind": (
        lambda t: evaluate(t, str(suite(t, terrains=[{"kind": LONG, "seeds": [0]}]))),
        "terrains[0].kind must be one of",
    ),
    "randomization": (
        lambda t: evaluate(
            t, str(suite(t, terrains=[{"kind": "flat", "seeds": [0], "randomization": {"friction": BIG}}]))
        ),
        "terrains[0].randomization.friction must be",
    ),
    "command": (
        lambda t: evaluate(t, str(suite(t, terrains=[{"kind": "flat", "seeds": [0], "command": {"vx": BIG}}]))),
        "terrains[0].command.vx must be",
    ),
    "robot foot radius": (
        lambda t: evaluate(t, "smoke", "--robot", str(robot(t, foot_radius=BIG))),
        "robot.yaml.foot_radius must be",
    ),
    "env kwargs": (
        lambda t: evaluate(t, "smoke", "--env-kwargs", json.dumps({"frame_skip": BIG})),
        "frame_skip must be",
    ),
    "training config": (
        lambda t: ["train", "--config", str(write(t / "train.yaml", {"algo": BIG})), "--out", str(t / "t")],
        "algo must be one of",
    ),
    "sweep config": (
        lambda t: ["sweep", "--config", str(write(t / "sweep.yaml", {"grid": BIG})), "--out", str(t / "w")],
        "grid must be a non-empty mapping",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_huge_value_is_shown_as_a_short_excerpt(tmp_path, capsys, case):
    argv, field = CASES[case]
    assert main(argv(tmp_path)) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err[:300]
    assert field in err and len(err) < MAX_MESSAGE, err[:300]

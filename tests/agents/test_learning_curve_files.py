"""``plot-curves`` on training folders whose files SB3 did not write: one ``error:`` line naming the file, the line
and the field (exit code 2), never a traceback and never a figure of lengths that cannot be.

The reference is the Monitor CSV format (``#{json}`` header line, then ``r,l,t[,extra]``: return, length in env steps,
seconds since the start) and EvalCallback's ``evaluations.npz`` (``timesteps`` (n,), ``results`` and ``ep_lengths``
(n, episodes)).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from agents.cli import main

HEADER = '#{"t_start": 1700000000.0, "env_id": "None"}'


def monitor(folder: Path, text: str | bytes) -> None:
    (folder / "monitor").mkdir(parents=True, exist_ok=True)
    path = folder / "monitor" / "0.monitor.csv"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())


def good_monitor(folder: Path) -> None:
    monitor(folder, f"{HEADER}\nr,l,t,ep_distance\n1.5,100,2.0,0.3\n2.5,120,4.0,0.4\n")


def evaluations(folder: Path, **arrays: object) -> None:
    (folder / "eval").mkdir(parents=True, exist_ok=True)
    good = {"timesteps": np.array([100, 200]), "results": np.array([[1.0], [2.0]]),
            "ep_lengths": np.array([[50], [60]])}  # fmt: skip
    np.savez(folder / "eval" / "evaluations.npz", **{k: v for k, v in {**good, **arrays}.items() if v is not None})


def garbage_npz(folder: Path, content: bytes) -> None:
    (folder / "eval").mkdir(parents=True, exist_ok=True)
    (folder / "eval" / "evaluations.npz").write_bytes(content)


CASES: dict[str, tuple[Callable[[Path], None], tuple[str, ...]]] = {
    "monitor without t": (lambda f: monitor(f, f"{HEADER}\nr,l\n1.0,100\n"), ("0.monitor.csv", "['t']", "missing")),
    "monitor without l": (lambda f: monitor(f, f"{HEADER}\nr,t\n1.0,2.0\n"), ("0.monitor.csv", "['l']", "missing")),
    "monitor without a header row": (lambda f: monitor(f, "1.0,100,2.0\n"), ("0.monitor.csv", "missing")),
    "monitor a binary file": (
        lambda f: monitor(f, bytes(range(256)) * 4),
        ("0.monitor.csv", "not a Monitor CSV"),
    ),
    "monitor with a NUL byte": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,1\x000,2\n"), ("0.monitor.csv",)),
    "length NaN": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,nan,2.0\n"), ("line 3", "l must be", "'nan'")),
    "length negative": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,-100,2.0\n"), ("line 3", "l must be", "'-100'")),
    "length zero": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,0,2.0\n"), ("l must be", ">= 1")),
    "length a fraction": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,12.5,2.0\n"), ("l must be", "'12.5'")),
    "length a word": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,ten,2.0\n"), ("l must be", "'ten'")),
    "return infinite": (lambda f: monitor(f, f"{HEADER}\nr,l,t\ninf,10,2.0\n"), ("line 3", "r must be a finite")),
    "time negative": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,10,-2.0\n"), ("line 3", "t must be", "'-2.0'")),
    "a value missing": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,10\n"), ("line 3", "3 values expected")),
    "a value too many": (lambda f: monitor(f, f"{HEADER}\nr,l,t\n1.0,10,2.0,7\n"), ("line 3", "3 values expected")),
    "evaluations garbage text": (
        lambda f: (good_monitor(f), garbage_npz(f, b"not an npz at all")),
        ("evaluations.npz", "EvalCallback"),
    ),
    "evaluations a truncated zip": (
        lambda f: (good_monitor(f), evaluations(f), garbage_npz(f, (f / "eval" / "evaluations.npz").read_bytes()[:60])),
        ("evaluations.npz", "EvalCallback"),
    ),
    "evaluations random bytes": (
        lambda f: (good_monitor(f), garbage_npz(f, b"PK\x03\x04" + bytes(range(256)) * 8)),
        ("evaluations.npz", "EvalCallback"),
    ),
    "evaluations without results": (
        lambda f: (good_monitor(f), evaluations(f, results=None)),
        ("evaluations.npz", "['results'] missing"),
    ),
    "evaluations of other shapes": (
        lambda f: (good_monitor(f), evaluations(f, results=np.array([1.0, 2.0]))),
        ("evaluations.npz", "shapes", "(n, episodes)"),
    ),
    "evaluations with NaN lengths": (
        lambda f: (good_monitor(f), evaluations(f, ep_lengths=np.array([[np.nan], [60.0]]))),
        ("evaluations.npz", "ep_lengths must be whole numbers of steps >= 1"),
    ),
    "evaluations with negative lengths": (
        lambda f: (good_monitor(f), evaluations(f, ep_lengths=np.array([[-5], [60]]))),
        ("evaluations.npz", "ep_lengths"),
    ),
    "evaluations with NaN returns": (
        lambda f: (good_monitor(f), evaluations(f, results=np.array([[np.nan], [1.0]]))),
        ("evaluations.npz", "results must be finite"),
    ),
    "evaluations of strings": (
        lambda f: (good_monitor(f), evaluations(f, timesteps=np.array(["a", "b"]))),
        ("evaluations.npz", "timesteps holds", "not numbers"),
    ),
}
"""A training folder's file that SB3 did not write: how it is made, and what the error line must name."""


@pytest.mark.parametrize("name", list(CASES))
def test_plot_curves_refuses_a_file_sb3_did_not_write_in_one_line(name, tmp_path, capsys):
    make, fields = CASES[name]
    run = tmp_path / "run"
    make(run)
    out = tmp_path / "fig.png"
    capsys.readouterr()
    rc = main(["plot-curves", str(run), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert [f for f in fields if f not in lines[0]] == [], lines[0]
    assert not out.exists()


def test_the_files_sb3_writes_are_read_as_written(tmp_path):
    """The checked readers return the values of well-formed files: the episodes in time order, cumulative steps."""
    from agents.rl.learning_curve import read_evaluations, read_monitor

    run = tmp_path / "run"
    monitor(run, f"{HEADER}\nr,l,t,ep_distance\n2.5,120,4.0,\n1.5,100,2.0,0.3\n")
    evaluations(run)
    mon = read_monitor(run / "monitor")
    np.testing.assert_array_equal(mon["r"], [1.5, 2.5])
    np.testing.assert_array_equal(mon["timesteps"], [100, 220])
    np.testing.assert_array_equal(mon["ep_distance"], [0.3, np.nan])  # an extra column may be empty
    ev = read_evaluations(run / "eval" / "evaluations.npz")
    np.testing.assert_array_equal(ev["timesteps"], [100, 200])
    np.testing.assert_array_equal(ev["lengths"], [50, 60])
    assert read_evaluations(run / "eval" / "missing.npz") is None

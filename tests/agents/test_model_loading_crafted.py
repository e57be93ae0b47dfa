"""Crafted model folders: every command that loads one (evaluate, export, train --init-from, robustness) exits 2
with one line ``error: ...`` naming the file and the field, prints no traceback, and runs no code from the folder.

The folders are made from one real run of ``quad-uneven train`` (a tiny PPO from scratch), then damaged one file
at a time: pickles in the zip's tensor files, a ``data`` entry of the wrong JSON type, recorded spaces of other
types, observation statistics of another length, NaN or complex, a ``rl_meta.json`` that is not UTF-8 or holds a
string where a bool belongs, and an ``--out`` that cannot be written.
"""

from __future__ import annotations

import io
import json
import pickle
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from agents.cli import main
from agents.rl.config import load_train_config
from quad_uneven_env.config import CONFIG_DIR

TINY_SCRATCH = {
    "timesteps": 64,
    "n_envs": 1,
    "vec_env": "dummy",
    "max_episode_steps": 40,
    "eval_freq": 0,
    "checkpoint_freq": 0,
    "time_limit_min": 0,
    "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 1},
    "policy_kwargs": {"net_arch": [16]},
}
"""Overrides of the shipped from-scratch PPO config for a run of a few seconds."""


class _Marker:
    """Unpickling this creates the file ``path``: proof that a loader ran code from the model folder."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[Path, Path]:
    """(the config, the run's folder) of a tiny ``quad-uneven train`` run: model.zip, statistics, rl_meta.json."""
    tmp = tmp_path_factory.mktemp("crafted")
    raw = yaml.safe_load((CONFIG_DIR / "rl" / "ppo_scratch.yaml").read_text())
    config = tmp / "tiny.yaml"
    config.write_text(yaml.safe_dump({**raw, **TINY_SCRATCH}))
    from agents.rl.training import train

    train(load_train_config(config), tmp / "run", progress=False)
    return config, tmp / "run"


@pytest.fixture
def folder(trained, tmp_path) -> Path:
    """A fresh copy of the trained run's model folder, to craft."""
    dst = tmp_path / "model"
    dst.mkdir()
    for name in ("model.zip", "model_obs_norm.npz", "rl_meta.json"):
        shutil.copy(trained[1] / name, dst / name)
    return dst


# ------------------------------------------------------------------------------------------------ crafting
def rewrite_zip(path: Path, change: Callable[[dict[str, bytes]], None]) -> None:
    """Apply ``change`` to the zip's entries (name -> bytes) and write them back."""
    with zipfile.ZipFile(path) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    change(entries)
    with zipfile.ZipFile(path, "w") as z:
        for name, blob in entries.items():
            z.writestr(name, blob)


def change_data(path: Path, change: Callable[[dict], object]) -> None:
    """Replace the zip's ``data`` JSON by ``change(data)``."""

    def edit(entries: dict[str, bytes]) -> None:
        entries["data"] = json.dumps(change(json.loads(entries["data"]))).encode()

    rewrite_zip(path, edit)


def torch_saved(obj: object) -> bytes:
    """``obj`` written by ``torch.save`` (a pickle inside torch's zip format)."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def change_meta(folder: Path, **changes: object) -> None:
    meta = json.loads((folder / "rl_meta.json").read_text())
    (folder / "rl_meta.json").write_text(json.dumps({**meta, **changes}))


def save_stats(folder: Path, **arrays: object) -> None:
    with np.load(folder / "model_obs_norm.npz") as z:
        stats = {k: z[k] for k in z.files}
    stats.update(arrays)
    with (folder / "model_obs_norm.npz").open("wb") as f:
        np.savez(f, **{k: v for k, v in stats.items() if v is not None})


def n_obs(folder: Path) -> int:
    with np.load(folder / "model_obs_norm.npz") as z:
        return int(z["mean"].shape[0])


# ---------------------------------------------------------------------------------------------- commands
def evaluate_argv(folder: Path, tmp: Path, *extra: str) -> list[str]:
    suite = tmp / "suite.yaml"
    suite.write_text(
        yaml.safe_dump(
            {"name": "tiny", "goal_distance": 0.5, "time_limit": 0.1, "terrains": [{"kind": "flat", "seeds": [0]}]}
        )
    )
    policy = str(folder / "model.zip")
    return ["evaluate", "--policy", policy, "--suite", str(suite), "--out", str(tmp / "eval"), "--no-progress", *extra]


def export_argv(folder: Path, tmp: Path, *extra: str) -> list[str]:
    return ["export", "--policy", str(folder / "model.zip"), "--out", str(tmp / "p.onnx"), *extra]


def train_argv(folder: Path, tmp: Path, config: Path) -> list[str]:
    return ["train", "--config", str(config), "--init-from", str(folder), "--out", str(tmp / "run"), "--no-progress"]


def robustness_argv(folder: Path, tmp: Path) -> list[str]:
    policy = str(folder / "model.zip")
    args = ["--values", "1.0", "--seeds", "1", "--goal", "0.5", "--no-progress"]
    return ["robustness", "--factor", "friction", "--policy", policy, "--out", str(tmp / "rob"), *args]


def fails_in_one_line(argv: list[str], capsys, *fields: str) -> str:
    """Run the CLI on ``argv``; assert exit 2, one line ``error: ...`` holding every field, no traceback."""
    capsys.readouterr()
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    missing = [f for f in fields if f not in lines[0]]
    assert not missing, f"{missing} not in {lines[0]}"
    return lines[0]


def every_command(
    folder: Path, tmp: Path, config: Path, capsys, *fields: str, commands=("evaluate", "export", "train")
):
    """The crafted ``folder`` fails the same way in each of ``commands``, before any output is written."""
    builders = {
        "evaluate": lambda: evaluate_argv(folder, tmp),
        "export": lambda: export_argv(folder, tmp),
        "train": lambda: train_argv(folder, tmp, config),
        "robustness": lambda: robustness_argv(folder, tmp),
    }
    for command in commands:
        fails_in_one_line(builders[command](), capsys, *fields)
    for out in ("p.onnx", "run"):  # refused before the output is touched
        assert not (tmp / out).exists(), f"{out} was written for a crafted folder"
    for out in ("eval", "rob"):  # the evaluation's folder may exist, empty: no episode ran
        written = [p.name for p in (tmp / out).rglob("*") if p.is_file()] if (tmp / out).exists() else []
        assert not written, f"{out} holds {written} for a crafted folder"


# ------------------------------------------------------------------------------------------------- tests
def test_the_untouched_folder_evaluates_exports_and_warm_starts(trained, folder, tmp_path, capsys):
    """The reference: the crafted cases below fail because of what was crafted, not because of the fixture."""
    config, _ = trained
    assert main(evaluate_argv(folder, tmp_path)) == 0
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert all(e["error"] is None for e in results["episodes"]), results["episodes"]
    pytest.importorskip("onnx")
    assert main(export_argv(folder, tmp_path)) == 0 and (tmp_path / "p.onnx").is_file()
    raw = yaml.safe_load(config.read_text())
    short = tmp_path / "short.yaml"
    short.write_text(yaml.safe_dump({**raw, "timesteps": 16}))
    assert main(train_argv(folder, tmp_path, short)) == 0


@pytest.mark.parametrize("entry", ["policy.pth", "pytorch_variables.pth", "extra.pth"])
@pytest.mark.parametrize("form", ["raw pickle", "torch.save"])
def test_a_pickle_in_a_tensor_file_is_refused_and_never_run(trained, folder, tmp_path, capsys, entry, form):
    marker = tmp_path / "PWNED"
    payload = pickle.dumps(_Marker(marker)) if form == "raw pickle" else torch_saved(_Marker(marker))
    rewrite_zip(folder / "model.zip", lambda e: e.__setitem__(entry, payload))
    every_command(folder, tmp_path, trained[0], capsys, "model.zip", entry, "weights_only",
                  commands=("evaluate", "export", "train", "robustness"))  # fmt: skip
    fails_in_one_line(evaluate_argv(folder, tmp_path, "--allow-pickle"), capsys, "model.zip", entry)
    assert not marker.exists(), "a pickle in the model zip ran"


def test_a_pickle_in_data_is_refused_unless_allowed_and_never_run_when_refused(trained, folder, tmp_path, capsys):
    import base64

    marker = tmp_path / "PWNED"
    payload = {":type:": "<class 'function'>", ":serialized:": base64.b64encode(pickle.dumps(_Marker(marker))).decode()}
    change_data(folder / "model.zip", lambda d: {**d, "my_hook": payload})
    every_command(folder, tmp_path, trained[0], capsys, "model.zip", "my_hook", "--allow-pickle",
                  commands=("evaluate", "export"))  # fmt: skip
    assert not marker.exists(), "a pickle in the model's data ran"


def _space(key: str, **changes: object) -> Callable[[dict], dict]:
    return lambda d: {**d, key: {**d[key], **changes}}


DATA_CASES: dict[str, tuple[Callable[[dict], object], tuple[str, ...]]] = {
    "list": (lambda d: list(d), ("'data'", "JSON object", "list")),
    "string": (lambda d: "a string", ("'data'", "JSON object", "str")),
    "space not recorded": (lambda d: {**d, "observation_space": 3}, ("data.observation_space", "recorded space")),
    "space of another type": (
        _space("action_space", **{":type:": "<class 'gymnasium.spaces.discrete.Discrete'>"}),
        ("data.action_space", "Discrete", "Box"),
    ),
    "shape not a list": (_space("observation_space", _shape="39"), ("data.observation_space._shape", "integers")),
    "another shape": (_space("observation_space", _shape=[7]), ("observation space", "(7,)")),
    "policy_kwargs a list": (lambda d: {**d, "policy_kwargs": ["net_arch"]}, ("data.policy_kwargs", "JSON object")),
    "n_steps a string": (lambda d: {**d, "n_steps": "1024"}, ("data.n_steps", "an integer")),
    "n_steps 0": (lambda d: {**d, "n_steps": 0}, ("data.n_steps", ">= 1")),
    "no policy class": (lambda d: {k: v for k, v in d.items() if k != "policy_class"}, ("data.policy_class",)),
}
"""Crafted ``data`` entries of the model zip: the change, and what the message must name."""


@pytest.mark.parametrize(("change", "fields"), list(DATA_CASES.values()), ids=list(DATA_CASES))
def test_a_data_entry_of_the_wrong_type_is_named(trained, folder, tmp_path, capsys, change, fields):
    change_data(folder / "model.zip", change)
    every_command(folder, tmp_path, trained[0], capsys, "model.zip", *fields, commands=("evaluate", "export"))


@pytest.mark.parametrize("form", ["list", "string"])
def test_warm_start_reads_the_data_entry_through_the_same_checks(trained, folder, tmp_path, capsys, form):
    change_data(folder / "model.zip", (lambda d: list(d)) if form == "list" else (lambda d: "x"))
    every_command(folder, tmp_path, trained[0], capsys, "init_from", "model.zip", "'data'", commands=("train",))


def _entry(name: str, blob: bytes) -> Callable[[dict[str, bytes]], None]:
    return lambda entries: entries.__setitem__(name, blob)


ENTRY_CASES: dict[str, tuple[Callable[[dict[str, bytes]], object], tuple[str, ...]]] = {
    "data not UTF-8": (_entry("data", b"\xff\xfe{}"), ("'data'", "UTF-8")),
    "no data": (lambda e: e.pop("data"), ("no 'data' entry",)),
    "foreign entry": (_entry("../evil.txt", b"x"), ("'../evil.txt'", "NAME.pth")),
    "non-tensor value": (_entry("policy.pth", torch_saved({"w": 1})), ("policy.pth", "'w' must be a tensor")),
    "not a dict": (_entry("policy.pth", torch_saved([torch.zeros(2)])), ("policy.pth", "dict of named tensors")),
    "garbage tensors": (_entry("policy.pth", b"\x00" * 64), ("policy.pth", "weights_only")),
    "too many entries": (lambda e: e.update({f"x{i}.pth": b"" for i in range(64)}), ("entries", "at most 64")),
    "optimizer state of another layout": (
        _entry("policy.optimizer.pth", torch_saved({"x": torch.zeros(1)})),
        ("policy.optimizer.pth", "optimizer state dict"),
    ),
}
"""Crafted entries of the model zip: the change, and what the message must name."""


@pytest.mark.parametrize(("change", "fields"), list(ENTRY_CASES.values()), ids=list(ENTRY_CASES))
def test_a_crafted_zip_entry_is_named(trained, folder, tmp_path, capsys, change, fields):
    rewrite_zip(folder / "model.zip", change)
    every_command(folder, tmp_path, trained[0], capsys, "model.zip", *fields)


def test_tensors_of_another_shape_are_refused(trained, folder, tmp_path, capsys):
    def shrink(entries: dict[str, bytes]) -> None:
        state = torch.load(io.BytesIO(entries["policy.pth"]), weights_only=True)
        entries["policy.pth"] = torch_saved({k: v[..., :1] if v.ndim else v for k, v in state.items()})

    rewrite_zip(folder / "model.zip", shrink)
    every_command(folder, tmp_path, trained[0], capsys, "model.zip", "RuntimeError", commands=("evaluate", "export"))
    # a warm start finds out when the config's model is built, in the run's folder: the error is the same one line
    fails_in_one_line(train_argv(folder, tmp_path, trained[0]), capsys, "init_from", "does not fit", "RuntimeError")


def test_an_entry_larger_than_the_cap_is_refused_from_its_header(folder, monkeypatch):
    from agents.rl import model_io

    monkeypatch.setattr(model_io, "MAX_ENTRY_BYTES", 1000)  # data holds about 19 kB
    with pytest.raises(model_io.ModelError, match=r"entry 'data' is \d+ bytes uncompressed, more than the 1000"):
        model_io.read_model_zip(folder / "model.zip")


def test_a_zip_entry_repeated_is_refused(trained, folder, tmp_path, capsys):
    with zipfile.ZipFile(folder / "model.zip", "a") as z, pytest.warns(UserWarning, match="Duplicate"):
        z.writestr("policy.pth", torch_saved({}))
    every_command(folder, tmp_path, trained[0], capsys, "model.zip", "'policy.pth' more than once")


@pytest.mark.parametrize(
    ("arrays", "fields"),
    [
        (lambda n: {"mean": np.zeros(n - 1), "var": np.ones(n - 1)}, ("model_obs_norm.npz", "shape", "observation")),
        (lambda n: {"mean": np.full(n, np.nan)}, ("model_obs_norm.npz", "mean", "finite")),
        (lambda n: {"var": np.ones(n) + 1j}, ("model_obs_norm.npz", "var", "real", "complex")),
        (lambda n: {"clip": np.array([1.0, 2.0])}, ("model_obs_norm.npz", "clip", "> 0")),
        (lambda n: {"epsilon": None}, ("model_obs_norm.npz", "epsilon")),
        (lambda n: {"extra": np.zeros(1)}, ("model_obs_norm.npz", "extra")),
    ],
    ids=["wrong length", "NaN", "complex", "clip not a scalar", "epsilon missing", "extra array"],
)
def test_observation_statistics_are_checked_before_any_episode(trained, folder, tmp_path, capsys, arrays, fields):
    save_stats(folder, **arrays(n_obs(folder)))
    every_command(folder, tmp_path, trained[0], capsys, *fields, commands=("evaluate", "export", "train", "robustness"))


def test_statistics_that_are_not_an_npz_of_arrays_are_refused(trained, folder, tmp_path, capsys):
    np.save(folder / "stats.npy", np.zeros(3))
    (folder / "stats.npy").replace(folder / "model_obs_norm.npz")
    every_command(folder, tmp_path, trained[0], capsys, "model_obs_norm.npz", "unreadable")
    with (folder / "model_obs_norm.npz").open("wb") as f:
        np.savez(f, mean=np.array([None, {}], dtype=object), var=np.ones(2), epsilon=1e-8, clip=10.0)
    every_command(folder, tmp_path, trained[0], capsys, "model_obs_norm.npz", "unreadable")


def test_metadata_that_is_not_utf8_is_named(trained, folder, tmp_path, capsys):
    (folder / "rl_meta.json").write_bytes(b'{"format": "quad-uneven-rl/1", "algo": "\xff\xfe"}')
    every_command(folder, tmp_path, trained[0], capsys, "rl_meta.json", "UTF-8",
                  commands=("evaluate", "export", "train", "robustness"))  # fmt: skip


META_CASES: dict[str, tuple[dict[str, object], tuple[str, ...]]] = {
    "expert_features a string": ({"expert_features": "no"}, ("expert_features", "true or false", "'no'")),
    "normalize_obs a number": ({"normalize_obs": 1}, ("normalize_obs", "true or false")),
    "residual a string": ({"residual": "false"}, ("residual", "true or false")),
    "residual_scale a string": ({"residual_scale": "0.1"}, ("residual_scale", "a finite number")),
    "residual_scale a bool": ({"residual_scale": True}, ("residual_scale", "a finite number")),
    "env_kwargs a list": ({"env_kwargs": ["terrain"]}, ("env_kwargs", "a JSON object")),
    "seed a fraction": ({"seed": 1.5}, ("seed", "an integer or null")),
    "algo null": ({"algo": None}, ("algo", "a string")),
}
"""Fields of ``rl_meta.json`` of the wrong JSON type: the change, and what the message must name."""


@pytest.mark.parametrize(("changes", "fields"), list(META_CASES.values()), ids=list(META_CASES))
def test_metadata_fields_of_the_wrong_json_type_are_named(trained, folder, tmp_path, capsys, changes, fields):
    change_meta(folder, **changes)
    every_command(folder, tmp_path, trained[0], capsys, "rl_meta.json", *fields)


def test_metadata_with_nan_is_refused(trained, folder, tmp_path, capsys):
    text = (folder / "rl_meta.json").read_text().replace('"seed": 0', '"seed": NaN')
    assert "NaN" in text
    (folder / "rl_meta.json").write_text(text)
    every_command(folder, tmp_path, trained[0], capsys, "rl_meta.json", "NaN")


def test_export_to_an_unwritable_out_names_it(folder, tmp_path, capsys):
    pytest.importorskip("onnx")
    (tmp_path / "a_file").write_text("x")
    line = fails_in_one_line(
        ["export", "--policy", str(folder / "model.zip"), "--out", str(tmp_path / "a_file" / "p.onnx")], capsys, "--out"
    )
    assert "a_file" in line
    too_long = tmp_path / ("p" * 300 + ".onnx")  # the folder is writable, the name is not (even for root)
    fails_in_one_line(["export", "--policy", str(folder / "model.zip"), "--out", str(too_long)], capsys, "--out")
    dangling = tmp_path / "link.onnx"  # passes the checks of --out, fails when the file is written
    dangling.symlink_to(tmp_path / "a_file" / "p.onnx")
    line = fails_in_one_line(["export", "--policy", str(folder / "model.zip"), "--out", str(dangling)], capsys, "--out")
    assert "cannot be written" in line and "link.onnx" in line


def test_the_payload_would_create_its_marker(tmp_path):
    """The marker checks above can fail: unpickling the payload (as a loader that trusts the file would) runs it."""
    for i, blob in enumerate((pickle.dumps(_Marker(tmp_path / "a")), torch_saved(_Marker(tmp_path / "b")))):
        handle = pickle.loads(blob) if i == 0 else torch.load(io.BytesIO(blob), weights_only=False)
        handle.close()
    assert (tmp_path / "a").exists() and (tmp_path / "b").exists()

"""A damaged kernel cache heals itself: an unreadable ``.nbi`` index or ``.nbc`` data file (truncated, garbage,
empty) is a cache miss, never a failed process. The folder holding it is set aside, the kernel compiled again and
cached anew, with one warning; the next process loads everything from the cache again.

Each case runs fresh processes (``QUAD_UNEVEN_CACHE_DIR`` at a tmp folder) on three kernel modules: two compiled at
import (explicit signatures: ``spatial_kernels``, ``robot.dynamics.mujoco_kernels``), one at its first call
(``planners.spline_kernels``, as inside a rollout). The kernels' results are compared with numpy's.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import json
import numba
import numpy as np
from quad_uneven_env import spatial_kernels as S
from quad_uneven_env.robot.dynamics import mujoco_kernels as M
from planners import spline_kernels as P

a = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]]); inv = np.empty((3, 3))
ok_inv = bool(S.inv3_into(a, inv)) and np.allclose(inv, np.linalg.inv(a))
q = np.array([np.cos(0.3), 0.0, 0.0, np.sin(0.3)]); R = np.empty((3, 3))  # 0.6 rad about z
S.quat_to_matrix_into(q, R)
ok_quat = np.allclose(R, [[np.cos(0.6), -np.sin(0.6), 0], [np.sin(0.6), np.cos(0.6), 0], [0, 0, 1]])
tau = np.array([0.0, 1.0]); y = np.array([[0.0], [2.0]]); v = np.zeros((2, 1)); t = np.array([0.5])
pos, vel, acc = (np.empty((1, 1)) for _ in range(3))
P.hermite_into(tau, y, v, t, pos, vel, acc)  # the smoothstep from 0 to 2: 1 at mid-time, slope 3
ok_spline = np.allclose([pos[0, 0], vel[0, 0]], [1.0, 3.0])
kernels = [d for m in (S, M, P) for d in vars(m).values() if isinstance(d, numba.core.registry.CPUDispatcher)]
print(json.dumps({"ok": ok_inv and ok_quat and ok_spline,
                  "hits": sum(sum(d.stats.cache_hits.values()) for d in kernels),
                  "misses": sum(sum(d.stats.cache_misses.values()) for d in kernels)}))
"""

FOLDERS = {"spatial": "quad_uneven_env", "mujoco": "quad_uneven_env.robot.dynamics", "spline": "planners"}
"""The kernel folder (of the fingerprint folder) each probed module caches into."""


def run_probe(cache: Path) -> tuple[dict, str]:
    env = {**os.environ, "QUAD_UNEVEN_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


@pytest.fixture(scope="module")
def filled(tmp_path_factory) -> Path:
    """A cache filled by one process: every probed kernel compiled and saved."""
    cache = tmp_path_factory.mktemp("kernels")
    result, _ = run_probe(cache)
    assert result["ok"] and result["hits"] == 0 and result["misses"] == 5
    return cache


def copy_of(cache: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A copy of the filled cache and its fingerprint folder."""
    copy = Path(shutil.copytree(cache, tmp_path / "cache"))
    (fingerprint,) = copy.glob("numba-*")
    return copy, fingerprint


def entry(fingerprint: Path, module: str, pattern: str) -> Path:
    (path,) = (fingerprint / FOLDERS[module]).glob(pattern)
    return path


DAMAGES = {
    "truncated": lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
    "garbage": lambda p: p.write_bytes(b"garbage, not a pickle\n" * 20),
    "empty": lambda p: p.write_bytes(b""),
    "random bytes": lambda p: p.write_bytes(bytes(range(256)) * 8),
}


QUICK = {("truncated", "nbi"), ("garbage", "nbc")}
"""Cases of the default suite; the others run with ``make test-slow`` (each case is a few fresh processes)."""


@pytest.mark.parametrize(
    ("damage", "suffix"),
    [
        pytest.param(d, s, marks=() if (d, s) in QUICK else pytest.mark.slow, id=f"{d}-{s}")
        for d in DAMAGES
        for s in ("nbi", "nbc")
    ],
)
def test_an_unreadable_entry_is_set_aside_and_compiled_again(filled, tmp_path, damage, suffix):
    cache, fingerprint = copy_of(filled, tmp_path)
    DAMAGES[damage](entry(fingerprint, "spatial", f"spatial_kernels.inv3_into-*.{suffix}"))
    result, err = run_probe(cache)
    assert result["ok"], err
    assert err.count("KernelCacheWarning") == 1 and "set aside" in err, err
    aside = list(fingerprint.glob("quad_uneven_env.unreadable-*"))
    assert len(aside) == 1 and str(aside[0]) in err
    assert result["misses"] == 2 and result["hits"] == 3  # both kernels of the set-aside folder compiled again


def test_damaged_entries_of_several_kernels_give_one_warning(filled, tmp_path):
    """A truncated index of a kernel compiled at import, a garbage data file of another module's and an empty
    index of a kernel compiled at its first call, in one cache: one process heals all three."""
    cache, fingerprint = copy_of(filled, tmp_path)
    DAMAGES["truncated"](entry(fingerprint, "spatial", "spatial_kernels.quat_to_matrix_into-*.nbi"))
    DAMAGES["garbage"](entry(fingerprint, "mujoco", "mujoco_kernels.mujoco_terms-*.nbc"))
    DAMAGES["empty"](entry(fingerprint, "spline", "spline_kernels.hermite_into-*.nbi"))
    result, err = run_probe(cache)
    assert result["ok"], err
    assert err.count("KernelCacheWarning") == 1, err
    for folder in FOLDERS.values():
        assert len(list(fingerprint.glob(f"{folder}.unreadable-*"))) == 1, folder
    for _ in range(2):  # kernels loaded before their folder was set aside are cached again by the next process
        result, err = run_probe(cache)
        assert result["ok"] and "KernelCacheWarning" not in err, err
    assert result["misses"] == 0 and result["hits"] == 5

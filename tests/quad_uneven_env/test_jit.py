"""The on-disk kernel cache (quad_uneven_env.jit): every kernel goes through it, a second process loads instead of
compiling, and a folder that cannot be written disables it without breaking anything."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from quad_uneven_env import jit

ROOT = Path(__file__).resolve().parents[2]

# A small kernel module (one compiled function) run in a fresh process; prints the dispatcher's cache statistics.
PROBE = """
import json, numba
from numba.core import config
import numpy as np
from quad_uneven_env import jit
from quad_uneven_env import spatial_kernels as S
a = np.eye(3); out = np.empty((3, 3))
ok = S.inv3_into(a, out) if hasattr(S, "inv3_into") else None
d = [v for v in vars(S).values() if isinstance(v, numba.core.registry.CPUDispatcher)]
print(json.dumps({"dir": None if jit.CACHE_DIR is None else str(jit.CACHE_DIR),
                  "hits": sum(sum(x.stats.cache_hits.values()) for x in d),
                  "misses": sum(sum(x.stats.cache_misses.values()) for x in d),
                  "numba_dir": config.CACHE_DIR}))
"""


def _probe(cache_dir: str) -> dict:
    env = {**os.environ, "QUAD_UNEVEN_CACHE_DIR": cache_dir, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_second_process_loads_the_kernels_instead_of_compiling(tmp_path):
    first = _probe(str(tmp_path))
    assert first["dir"] is not None and Path(first["dir"]).parent == tmp_path
    assert first["hits"] == 0  # an empty cache: everything compiled here (explicit signatures compile at import)
    assert any(Path(first["dir"]).rglob("*.nbi")), "no cache index written"
    second = _probe(str(tmp_path))
    assert second["hits"] > 0 and second["misses"] == 0
    assert second["numba_dir"] == first["numba_dir"]  # numba's own setting is left as it was


def test_an_unwritable_cache_folder_disables_the_cache(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    result = _probe(str(blocker / "cache"))
    assert result["dir"] is None and result["hits"] == 0


def test_every_kernel_module_compiles_through_the_cached_njit():
    sources = jit.kernel_sources()
    assert len(sources) >= 15
    for path in sources:
        text = path.read_text()
        assert not re.search(r"\b(nb|numba)\.(njit|jit)\(", text), f"{path} compiles outside quad_uneven_env.jit"
        assert "from quad_uneven_env.jit import njit" in text, path


def test_the_cache_folder_changes_with_any_kernel_source(tmp_path):
    kernel = tmp_path / "agents" / "control" / "extra_kernels.py"
    kernel.parent.mkdir(parents=True)
    kernel.write_text("x = 1\n")
    (tmp_path / "planners").mkdir()
    (tmp_path / "planners" / "helpers.py").write_text("y = 1\n")  # not a kernel module: not in the fingerprint
    first = jit.kernel_fingerprint(tmp_path)
    assert jit.kernel_sources(tmp_path) == [kernel]
    (tmp_path / "planners" / "helpers.py").write_text("y = 2\n")
    assert jit.kernel_fingerprint(tmp_path) == first
    kernel.write_text("x = 2\n")
    assert jit.kernel_fingerprint(tmp_path) != first
    kernel.write_text("x = 1\n")
    assert jit.kernel_fingerprint(tmp_path) == first

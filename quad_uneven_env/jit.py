"""One way to compile a kernel: numba's ``njit`` with an on-disk cache that outlives the process.

Every ``*_kernels.py`` module of the three packages compiles with :func:`njit`, so a new process (a CLI call,
an evaluation worker, a vector-env copy, a Ray task, a test) loads the machine code compiled by an earlier one
instead of compiling again (about 50 s for the expert's kernels).

Where the cache lives: ``$QUAD_UNEVEN_CACHE_DIR``, else ``$XDG_CACHE_HOME/quad-uneven``, else
``~/.cache/quad-uneven``; never inside the installed package, which may be read-only. Inside it, one folder
per fingerprint of every kernel module's source, the package version and numba's version: numba checks only
the source file of the function it loads, so a kernel that calls a kernel of another module would otherwise
keep a stale copy of its callee after an upgrade or an edit. A folder that cannot be created or written
disables the cache (kernels are then compiled in every process, as without it). ``NUMBA_CACHE_DIR``, numba's
own setting, is left to numba for other code: only this package's kernels use the folder above.

A cache entry that cannot be read (a truncated or garbage ``.nbi`` index or ``.nbc`` data file: a full disk, a
killed copy, a user's edit) is a cache miss, never a failed process: :class:`HealingFunctionCache` sets the
kernel folder that holds it aside (renamed ``NAME.unreadable-PID-N``, for a look; delete it at will), compiles
the kernel again into a fresh folder and warns once per process (:class:`KernelCacheWarning`).
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import os
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numba as nb
import numba.core.dispatcher as _numba_dispatcher
from numba.core import config as _numba_config
from numba.core.caching import FunctionCache, UserProvidedCacheLocator

from quad_uneven_env.fields import clip

_PACKAGES = ("quad_uneven_env", "planners", "agents")
_ROOT = Path(__file__).resolve().parent.parent


def kernel_sources(root: Path = _ROOT) -> list[Path]:
    """The source files of every compiled kernel module (``*_kernels.py``) of the three packages under ``root``
    (default: where they are installed), sorted."""
    return sorted(p for pkg in _PACKAGES for p in (root / pkg).rglob("*_kernels.py"))


def kernel_fingerprint(root: Path = _ROOT) -> str:
    """12 hex digits of the kernels' sources under ``root``, this package's version and numba's version."""
    from quad_uneven_env import __version__

    digest = hashlib.sha256(f"{__version__}|{nb.__version__}".encode())
    for path in kernel_sources(root):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def cache_root() -> Path:
    """The folder that holds the caches of every version (``$QUAD_UNEVEN_CACHE_DIR``, else the XDG cache)."""
    explicit = os.environ.get("QUAD_UNEVEN_CACHE_DIR")
    if explicit:
        return Path(explicit).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "quad-uneven"


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def _cache_dir() -> Path | None:
    folder = cache_root() / f"numba-{kernel_fingerprint()}"
    return folder if _writable(folder) else None


CACHE_DIR: Path | None = _cache_dir()
"""Where this package's compiled kernels are cached (None: not cached, the folder is not writable)."""


class PackageCacheLocator(UserProvidedCacheLocator):
    """numba's locator for a user-given cache folder, with a kernel's subfolder named by its module's place in the
    package (``agents.control``) instead of a hash of its absolute path: a copy of the same sources elsewhere (a
    wheel installed after a checkout, a second virtual environment) finds the machine code already compiled.
    numba still checks each source file's content hash before it loads anything."""

    @classmethod
    def get_suitable_cache_subpath(cls, py_file: str) -> str:
        folder = Path(py_file).resolve().parent
        try:
            return ".".join(folder.relative_to(_ROOT).parts)
        except ValueError:  # not one of this package's files
            return super().get_suitable_cache_subpath(py_file)


class KernelCacheWarning(UserWarning):
    """An entry of the kernel cache could not be read (or written): its folder was set aside, the kernels compiled
    again."""


_set_aside_count = itertools.count()
_warned = False


def _set_aside(folder: Path, action: str, err: Exception) -> None:
    """Rename the kernel cache ``folder`` (one package's kernels) ``NAME.unreadable-PID-N`` after ``err`` while
    ``action`` (a loaded kernel stays loaded; the others are compiled again and cached in a fresh folder), and warn
    once per process. Another process may have moved it first: then nothing is renamed."""
    global _warned
    target = folder.with_name(f"{folder.name}.unreadable-{os.getpid()}-{next(_set_aside_count)}")
    try:
        folder.rename(target)
        where = f"set aside as {target}"
    except OSError:  # gone already (another process set it aside) or not renamable: the compiled kernel is not cached
        where = "left in place"
    if not _warned:
        _warned = True
        message = (
            f"quad-uneven: the compiled-kernel cache {folder} failed while {action} ({type(err).__name__}: "
            f"{clip(str(err))}); it was {where} and its kernels are compiled again"
        )
        warnings.warn(message, KernelCacheWarning, stacklevel=2)


class HealingFunctionCache(FunctionCache):
    """numba's on-disk cache of one kernel, which takes an entry it cannot read for a cache miss.

    numba unpickles its index (``.nbi``) and data (``.nbc``) files and rebuilds the machine code from them; a
    truncated or garbage file raises whatever the unpickler or the rebuild raises (``UnpicklingError``,
    ``EOFError``, ``MemoryError``, ...) at import or at a kernel's first call. Here any such error sets the kernel's
    folder aside (:func:`_set_aside`) and the kernel is compiled instead; a write that fails is skipped the same way.
    """

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        """The cached compile result of ``sig``, or None (compile it) if there is none or it cannot be read."""
        try:
            return super().load_overload(sig, target_context)
        except Exception as err:  # a damaged cache file can raise any error while it is unpickled and rebuilt
            _set_aside(Path(self.cache_path), "loading a kernel", err)
            return None

    def save_overload(self, sig: Any, data: Any) -> None:
        """Cache the compile result ``data`` of ``sig``; a folder that cannot take it is set aside instead."""
        try:
            super().save_overload(sig, data)
        except Exception as err:  # a damaged index read back before the write, a full disk
            _set_aside(Path(self.cache_path), "saving a kernel", err)


@contextlib.contextmanager
def _numba_cache_dir(folder: Path) -> Iterator[None]:
    """numba reads its cache settings when a function is decorated: point them at ``folder``,
    :class:`PackageCacheLocator` and :class:`HealingFunctionCache` (the cache class ``Dispatcher.enable_caching``
    makes) for that moment only."""
    saved = _numba_config.CACHE_DIR, _numba_config.CACHE_LOCATOR_CLASSES, _numba_dispatcher.FunctionCache
    _numba_config.CACHE_DIR = str(folder)
    _numba_config.CACHE_LOCATOR_CLASSES = f"{__name__}.{PackageCacheLocator.__name__}"
    _numba_dispatcher.FunctionCache = HealingFunctionCache
    try:
        yield
    finally:
        _numba_config.CACHE_DIR, _numba_config.CACHE_LOCATOR_CLASSES, _numba_dispatcher.FunctionCache = saved


def njit(*signature: Any, **options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(*signature, **options)`` with the on-disk cache in :data:`CACHE_DIR` (when it is writable).

    Use it as a decorator factory, always with parentheses: ``@njit()``, ``@njit(nb.void(...), nogil=True)``.
    """
    if "cache" in options:
        raise ValueError("njit: the cache is this module's setting, do not pass cache=")

    def decorate(func: Callable[..., Any]) -> Any:
        if CACHE_DIR is None:
            return nb.njit(*signature, cache=False, **options)(func)
        try:
            with _numba_cache_dir(CACHE_DIR):
                return nb.njit(*signature, cache=True, **options)(func)
        except RuntimeError:  # numba found no usable cache folder for this file after all
            return nb.njit(*signature, cache=False, **options)(func)

    return decorate


__all__ = [
    "CACHE_DIR",
    "HealingFunctionCache",
    "KernelCacheWarning",
    "PackageCacheLocator",
    "cache_root",
    "kernel_fingerprint",
    "kernel_sources",
    "njit",
]

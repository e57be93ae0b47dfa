"""Output directories of the commands: named, created, locked and checked before any work; a manifest of what the
command wrote.

Every command that writes into a directory the user names (``evaluate``, ``collect``, ``train``, ``distill``,
``select``, ``sweep``, ``robustness``, ``compare``, ``paper``, ``plan-paper``, ``demo``) owns it through
:func:`output_dir` for as long as it writes there: a name the file system cannot hold, an ``--out`` that is a file, or
one that cannot be created fails at once, before anything is simulated or trained; then the directory is locked
(:data:`LOCK_FILE`, :func:`fcntl.flock`): a second run into it, at the same time, refuses in one line naming the run
that holds it (``--resume`` and ``--overwrite`` included), and the lock goes with the process that holds it, however
that process ends. Under the lock, a command that must not mix its files with an older run's (``evaluate``,
``collect``, ``train``, ``distill``, ``select``, ``sweep``) refuses a non-empty directory (:class:`OutputError` naming
what is there) unless asked to resume or overwrite. A command that writes one file (``export``, ``plot-curves``,
``fit-strength``, ``demo --gif``) checks it with :func:`output_file`.

Each command records the files it writes, as it writes them, in the directory's manifest
(:data:`MANIFEST_FILE`, :class:`OutputManifest`, replaced atomically on every update). ``--overwrite`` deletes
exactly the files the manifest lists (and then the folders the command created, if empty); any other file,
whatever its name, stays. A directory holding outputs of the command's kind (its top-level names) but no manifest
(written by a release that kept none) is refused rather than guessed at: the message names it, the user deletes it.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import fcntl
import fnmatch
import json
import os
import shlex
import socket
import sys
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from quad_uneven_env.fields import clip, excerpt

__all__ = [
    "LOCK_FILE",
    "MANIFEST_FILE",
    "OutputError",
    "OutputInUse",
    "OutputManifest",
    "output_dir",
    "output_file",
    "owned_entries",
    "write_json_atomic",
]

MAX_NAMED = 5
"""At most this many stale entries are named in an error message."""

MAX_COMMAND_CHARS = 160
"""At most this many characters of the holder's command line are quoted when a locked directory is refused."""


OVERWRITE_HINT = (
    "pass --overwrite to delete the outputs of the earlier run (other files are kept) or choose another directory"
)
"""What the refusal of a non-empty output directory suggests by default."""


class OutputError(ValueError):
    """An output directory or file that cannot be used (a file, not creatable, or holding an older run's files)."""


class OutputInUse(OutputError):
    """An output directory another run holds (its lock file names the run)."""


def owned_entries(out: Path, owned: Sequence[str]) -> list[Path]:
    """Entries of ``out`` whose name matches one of the glob patterns ``owned`` (sorted; [] if ``out`` is missing)."""
    if not out.is_dir():
        return []
    return sorted(p for p in out.iterdir() if any(fnmatch.fnmatch(p.name, pat) for pat in owned))


def _names(paths: Sequence[Path]) -> str:
    shown = ", ".join(p.name + ("/" if p.is_dir() else "") for p in paths[:MAX_NAMED])
    return shown + (f" and {len(paths) - MAX_NAMED} more" if len(paths) > MAX_NAMED else "")


def _fs_error(field: str, path: Path, err: OSError, what: str = "cannot be used") -> OutputError:
    return OutputError(f"{field} {str(path)!r} {what} ({err.strerror or err})")


def check_path_name(path: str | os.PathLike[str], field: str = "--out") -> Path:
    """``path`` as a Path, if the file system can name it: every component within the file system's ``NAME_MAX``
    (255 bytes on most) and the whole within ``PATH_MAX``; no file is touched.

    :raises OutputError: naming ``field`` and the component that is too long.
    """
    p = Path(path)
    full = p if p.is_absolute() else Path.cwd() / p
    existing = next((a for a in (full, *full.parents) if os.path.isdir(a)), Path("/"))
    try:
        name_max, path_max = os.pathconf(existing, "PC_NAME_MAX"), os.pathconf(existing, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    for part in full.parts[1:]:
        size = len(os.fsencode(part))
        if size > name_max:
            raise OutputError(
                f"{field} {excerpt(str(p))}: the name {excerpt(part, 40)} is {size} bytes; the file system allows "
                f"at most {name_max}"
            )
    size = len(os.fsencode(str(full)))
    if size >= path_max:
        raise OutputError(f"{field} {excerpt(str(p))} is {size} bytes long; the file system allows {path_max - 1}")
    return p


# ----------------------------------------------------------------------------------------------------- the lock
LOCK_FILE = ".quad-uneven-lock"
"""The lock of an output directory: held (:func:`fcntl.flock`) by the run that writes there, which writes its pid,
host, command and start time into it; deleted when that run ends (a leftover one, of a run that was killed, holds
no lock and is taken over)."""


def _holder_text(fd: int) -> str:
    """The holder a lock file names, as text for a message."""
    try:
        info = json.loads(os.pread(fd, 4096, 0).decode())
        argv = clip(str(info["argv"]), MAX_COMMAND_CHARS)
        return f"{info['command']}, pid {int(info['pid'])} on {info['host']}, since {info['started']}: {argv}"
    except (OSError, ValueError, KeyError, TypeError):
        return "a run that is starting"


class OutputLock:
    """Exclusive ownership of the output directory ``out`` by this process, held until :meth:`release`.

    The lock is :func:`fcntl.flock` on ``out/``:data:`LOCK_FILE` (the kernel drops it when the process ends, however
    it ends); the file names the holder for the message of the run that is refused.
    """

    def __init__(self, out: Path, command: str, field: str = "--out") -> None:
        """Take the lock of ``out`` (an existing directory).

        :raises OutputInUse: if another run holds it (the message names that run: pid, host, start, command line).
        :raises OutputError: if the lock file cannot be written.
        """
        self.path = out / LOCK_FILE
        try:
            while True:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError as err:
                    holder = _holder_text(fd)
                    os.close(fd)
                    if err.errno not in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES):
                        raise
                    raise OutputInUse(
                        f"{field} {str(out)!r} is in use by another run ({holder}); wait for it to end or choose "
                        "another directory"
                    ) from None
                try:  # the holder may have released (and deleted) the file between our open and our lock
                    here, there = os.fstat(fd), os.stat(self.path)
                    if (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino):
                        break
                except FileNotFoundError:
                    pass
                os.close(fd)
            info = {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "command": command,
                "started": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                "argv": shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv and sys.argv[0] else command,
            }
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(info).encode(), 0)
        except OutputError:
            raise
        except OSError as err:
            raise _fs_error(field, out, err, f"cannot be locked: {LOCK_FILE}") from None
        self._fd: int | None = fd

    def release(self) -> None:
        """Delete the lock file and drop the lock (idempotent)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(self._fd)
        self._fd = None


# -------------------------------------------------------------------------------------------------- the routine
def _check_contents(path: Path, owned: Sequence[str], overwrite: bool, keep: bool, field: str, hint: str) -> None:
    """Refuse a non-empty ``path`` (its manifest and lock file aside), or delete its ``owned`` entries."""
    if keep:
        return
    if overwrite:
        delete_recorded_outputs(path, owned, field)
        return
    present = sorted(p for p in path.iterdir() if p.name not in (MANIFEST_FILE, LOCK_FILE))
    if present:
        raise OutputError(f"{field} {str(path)!r} is not empty ({_names(present)}); {hint}")


@contextlib.contextmanager
def output_dir(
    out: str | os.PathLike[str],
    command: str,
    owned: Sequence[str] = (),
    overwrite: bool = False,
    keep: bool = False,
    field: str = "--out",
    hint: str = OVERWRITE_HINT,
) -> Iterator[OutputManifest]:
    """Own the output directory ``out`` while the ``with`` block runs: check its name, create it, lock it, refuse
    an earlier run's files (or delete them), and record what the block writes in its manifest.

    The lock is taken before the contents are looked at and released when the block ends (normally, on an error
    or an interrupt): a second run into ``out`` at the same time is refused, whatever its options.

    :param command: the command's name, recorded in the manifest and the lock file (``evaluate``, ``train``, ...).
    :param owned: glob patterns of the top-level names the command writes (files or folders): a directory holding
        one of them but no manifest is refused by ``overwrite`` (see :func:`delete_recorded_outputs`).
    :param overwrite: delete the files the directory's manifest lists instead of refusing a non-empty directory
        (any other file is kept).
    :param keep: accept a non-empty directory as it is (resuming a run, or a command that replaces only its own
        files; the caller checks them).
    :param field: the name the messages use for ``out`` (e.g. ``--out``).
    :param hint: what the refusal of a non-empty directory suggests.
    :return: the directory's :class:`OutputManifest` (its ``out`` is ``out`` as a Path).
    :raises OutputError: if ``out`` cannot be named, is a file, cannot be created or written, is not empty while
        neither ``overwrite`` nor ``keep`` is set (the message names its entries), or ``overwrite`` meets outputs
        without a manifest or a file the manifest does not list where the command writes one;
        :class:`OutputInUse` if another run holds it.
    """
    path = check_path_name(out, field)
    try:
        if path.exists() and not path.is_dir():
            raise OutputError(f"{field} {str(path)!r} is a file, not a directory")
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise _fs_error(field, path, err, "cannot be created") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise OutputError(f"{field} {str(path)!r} is not writable")
    lock = OutputLock(path, command, field)
    try:
        try:
            _check_contents(path, owned, overwrite, keep, field, hint)
        except OSError as err:
            raise _fs_error(field, path, err) from None
        with OutputManifest(path, command) as manifest:
            yield manifest
    finally:
        lock.release()


def output_file(
    path: str | os.PathLike[str], field: str = "--out", overwrite: bool = True, suffix: str | None = None
) -> Path:
    """Check the output file ``path`` before any work and create its folder: a name the file system can hold, not
    a directory, the ``suffix`` if one is required, absent unless ``overwrite``.

    :return: ``path`` as a Path (its folder exists afterwards).
    :raises OutputError: naming ``field`` and what is wrong.
    """
    p = check_path_name(path, field)
    what = "file" if suffix is None else f"{suffix} file"
    if suffix is not None and p.suffix.lower() != suffix:
        raise OutputError(f"{field} must be a {suffix} file, got {str(p)!r}")
    try:
        if p.is_dir():
            raise OutputError(f"{field} {str(p)!r} is a directory; give the {what} to write")
        if p.exists() and not overwrite:
            raise OutputError(f"{field} {str(p)!r} exists; pass --overwrite to replace it")
        if p.parent.exists() and not p.parent.is_dir():
            raise OutputError(f"{field} {str(p)!r}: its folder {str(p.parent)!r} is a file")
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise _fs_error(field, p, err, "cannot be written") from None
    if not os.access(p.parent, os.W_OK | os.X_OK):
        raise OutputError(f"{field} {str(p)!r} cannot be written: its folder is not writable")
    return p


def write_json_atomic(path: Path, data: Any) -> Path:
    """Write ``data`` as strict JSON (no NaN or inf) to ``path`` via a temporary file and a rename.

    A reader never sees a half-written file: either the old content (or none) or the new one.
    :raises OSError: if the file cannot be written (the temporary file is removed).
    :raises ValueError: if ``data`` holds NaN or inf.
    """
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(json.dumps(data, indent=2, allow_nan=False))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


MANIFEST_FILE = ".quad-uneven-manifest.json"
"""The manifest of an output directory: the files the commands wrote there (relative POSIX paths)."""

MANIFEST_FORMAT = "quad-uneven-manifest/1"
"""Value of the manifest's ``format`` field."""


def _tmp_name(name: str) -> str:
    """The temporary name :func:`write_json_atomic` (and the evaluation's array writer) use for ``name``."""
    return f".{name}.tmp"


def _relative(out: Path, path: str | os.PathLike[str]) -> str:
    """``path`` (absolute, or relative to the working directory) as a POSIX path relative to ``out``."""
    p = Path(path)
    base = out.resolve()
    full = (p if p.is_absolute() else Path.cwd() / p).parent.resolve() / p.name
    try:
        return full.relative_to(base).as_posix()
    except ValueError:
        raise ValueError(f"{path} lies outside the output directory {out}") from None


def _walk(out: Path) -> tuple[set[str], set[str]]:
    """(files, folders) under ``out``, relative POSIX paths (symlinks count as files; not followed)."""
    files, dirs = set(), set()
    for root, subdirs, names in os.walk(out):
        rel = Path(root).relative_to(out)
        for d in list(subdirs):
            if (Path(root) / d).is_symlink():
                subdirs.remove(d)
                names.append(d)
            else:
                dirs.add((rel / d).as_posix())
        files.update((rel / n).as_posix() for n in names)
    return files, dirs


def read_manifest(out: Path, field: str = "out") -> dict[str, list[str]] | None:
    """The manifest of ``out`` (``{"files": [...], "dirs": [...]}``), None if it has none.

    :raises OutputError: if the manifest is not one quad-uneven wrote (unreadable, other fields, a path that
        leaves ``out``); nothing is deleted then.
    """
    path = out / MANIFEST_FILE
    if not path.is_file():
        return None

    def bad(why: str) -> OutputError:
        return OutputError(
            f"{field} {str(out)!r}: {MANIFEST_FILE} is not a manifest quad-uneven wrote ({why}); nothing was "
            "deleted: delete the old outputs yourself or choose another directory"
        )

    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise bad(str(err)) from None
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
        raise bad(f"format must be {MANIFEST_FORMAT!r}")
    lists = {}
    for key in ("files", "dirs"):
        items = data.get(key)
        if not isinstance(items, list) or not all(isinstance(x, str) for x in items):
            raise bad(f"{key} must be a list of paths")
        for x in items:
            parts = Path(x).parts
            if not x or Path(x).is_absolute() or ".." in parts or x == MANIFEST_FILE:
                raise bad(f"{key} lists {excerpt(x)}, a path outside the directory")
        lists[key] = list(items)
    return lists


def _inside(out: Path, rel: str) -> Path | None:
    """``out / rel`` if its folder (symlinks resolved) lies in ``out``, else None (never delete elsewhere)."""
    p = out / rel
    return p if p.parent.resolve().is_relative_to(out.resolve()) else None


def delete_recorded_outputs(out: Path, owned: Sequence[str] = (), field: str = "out") -> list[str]:
    """Delete what the manifest of ``out`` lists: its files (and their leftover temporary files), then its
    folders that are empty, then the manifest. Other files stay, whatever their names.

    Without a manifest, nothing is deleted: a directory with an entry matching ``owned`` (outputs of a release
    that wrote no manifest) is refused; one without is left as it is.

    :return: the relative paths deleted.
    :raises OutputError: on outputs without a manifest, a file the command writes (a literal name of
        ``owned``) that the manifest does not list, an invalid manifest, or a file that cannot be deleted.
    """
    manifest = read_manifest(out, field)
    if manifest is None:
        legacy = owned_entries(out, owned)
        if legacy:
            raise OutputError(
                f"{field} {str(out)!r} holds outputs ({_names(legacy)}) but no {MANIFEST_FILE} listing the files "
                "quad-uneven wrote (a release that kept no manifest wrote them): nothing was deleted; delete them "
                "yourself or choose another directory"
            )
        return []
    listed = set(manifest["files"])
    foreign = [
        p for p in owned_entries(out, [n for n in owned if not any(c in n for c in "*?[")])
        if p.is_file() and p.name not in listed
    ]  # fmt: skip
    if foreign:
        raise OutputError(
            f"{field} {str(out)!r} holds {_names(foreign)}, which its {MANIFEST_FILE} does not list (not written "
            "by quad-uneven) and which the command would replace: nothing was deleted; move it or choose another "
            "directory"
        )
    deleted = []
    try:
        for rel in sorted(listed):
            p = _inside(out, rel)
            if p is None:
                continue
            for victim in (p, p.with_name(_tmp_name(p.name))):
                if victim.is_symlink() or victim.is_file():
                    victim.unlink()
                    deleted.append(victim.relative_to(out).as_posix())
        for rel in sorted(manifest["dirs"], key=lambda d: -len(Path(d).parts)):
            d = _inside(out, rel)
            if d is None or d.is_symlink() or not d.is_dir():
                continue
            for leftover in d.glob(".*.tmp"):  # a temporary file of an interrupted write, in a folder of ours
                if leftover.is_file():
                    leftover.unlink()
            if not any(d.iterdir()):
                d.rmdir()
                deleted.append(rel + "/")
        (out / MANIFEST_FILE).unlink()
    except OSError as err:
        raise OutputError(f"{field} {str(out)!r}: cannot delete an old output ({err})") from None
    return deleted


class OutputManifest:
    """The files a command writes in its output directory ``out``, recorded in ``out/``:data:`MANIFEST_FILE`.

    Opened by :func:`output_dir`, it takes the existing manifest (a resumed run's) and notes what
    ``out`` holds. :meth:`add` records files as they are written (the manifest is replaced atomically each time);
    used as a context manager, it also records, on leaving (normally, on an error or an interrupt), every file
    that appeared in ``out`` meanwhile (what libraries wrote: checkpoints, plots, nested evaluations). Folders
    that did not exist are recorded as the command's, to be removed by ``--overwrite`` once empty.
    """

    def __init__(self, out: str | os.PathLike[str], command: str) -> None:
        self.out = Path(out)
        self.command = command
        old = read_manifest(self.out, "--out") or {"files": [], "dirs": []}
        self.files, self.dirs = set(old["files"]), set(old["dirs"])
        self._before_files, self._before_dirs = _walk(self.out)

    def add(self, paths: Iterable[str | os.PathLike[str]]) -> None:
        """Record ``paths`` (files in ``out``) and the folders between them and ``out`` that the command made.

        :raises OutputError: if the manifest cannot be written.
        """
        for path in paths:
            rel = _relative(self.out, path)
            self.files.add(rel)
            for parent in Path(rel).parents:
                d = parent.as_posix()
                if d != "." and d not in self._before_dirs:
                    self.dirs.add(d)
        self.write()

    def add_new(self) -> None:
        """Record every file and folder that appeared in ``out`` since this manifest was opened."""
        files, dirs = _walk(self.out)
        new = {f for f in files - self._before_files if f not in (MANIFEST_FILE, LOCK_FILE) and not f.endswith(".tmp")}
        self.dirs |= dirs - self._before_dirs
        if new or self.files:  # a command that wrote no file (refused its input) leaves no manifest
            self.add(self.out / f for f in sorted(new))

    def write(self) -> Path:
        """Write the manifest (atomically)."""
        data = {"format": MANIFEST_FORMAT, "command": self.command, "files": sorted(self.files),
                "dirs": sorted(self.dirs)}  # fmt: skip
        try:
            return write_json_atomic(self.out / MANIFEST_FILE, data)
        except OSError as err:
            raise OutputError(f"--out {str(self.out)!r}: cannot write {MANIFEST_FILE} ({err})") from None

    def __enter__(self) -> OutputManifest:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self.out.is_dir():
            self.add_new()

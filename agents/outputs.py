"""Output directories of the commands: checked and created before any work; a manifest of what the command wrote.

Every command that writes into a directory the user names (``evaluate``, ``train``, ``select``, ``sweep``,
``robustness``, ``compare``, ``paper``, ``plan-paper``, ``demo``) calls :func:`prepare_output_dir` before it
simulates or trains anything: an ``--out`` that is a file, or that cannot be created, fails at once. A command
that must not mix its files with an older run's (``evaluate``, ``train``, ``select``, ``sweep``) refuses a
non-empty directory (:class:`OutputError` naming what is there) unless asked to overwrite.

Each command records the files it writes, as it writes them, in the directory's manifest
(:data:`MANIFEST_FILE`, :class:`OutputManifest`, replaced atomically on every update). ``--overwrite`` deletes
exactly the files the manifest lists (and then the folders the command created, if empty); any other file,
whatever its name, stays. A directory holding outputs of the command's kind (its top-level names) but no manifest
(written by a release that kept none) is refused rather than guessed at: the message names it, the user deletes it.
"""

from __future__ import annotations

import fnmatch
import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from quad_uneven_env.fields import excerpt

__all__ = [
    "MANIFEST_FILE",
    "OutputError",
    "OutputManifest",
    "owned_entries",
    "prepare_output_dir",
    "write_json_atomic",
]

MAX_NAMED = 5
"""At most this many stale entries are named in an error message."""


OVERWRITE_HINT = (
    "pass --overwrite to delete the outputs of the earlier run (other files are kept) or choose another directory"
)
"""What the refusal of a non-empty output directory suggests by default."""


class OutputError(ValueError):
    """An output directory that cannot be used (a file, not creatable, or holding an older run's files)."""


def owned_entries(out: Path, owned: Sequence[str]) -> list[Path]:
    """Entries of ``out`` whose name matches one of the glob patterns ``owned`` (sorted; [] if ``out`` is missing)."""
    if not out.is_dir():
        return []
    return sorted(p for p in out.iterdir() if any(fnmatch.fnmatch(p.name, pat) for pat in owned))


def _names(paths: Sequence[Path]) -> str:
    shown = ", ".join(p.name + ("/" if p.is_dir() else "") for p in paths[:MAX_NAMED])
    return shown + (f" and {len(paths) - MAX_NAMED} more" if len(paths) > MAX_NAMED else "")


def prepare_output_dir(
    out: str | os.PathLike[str],
    owned: Sequence[str] = (),
    overwrite: bool = False,
    keep: bool = False,
    field: str = "out",
    hint: str = OVERWRITE_HINT,
) -> Path:
    """Check and create the output directory ``out``; refuse a non-empty one, or delete the ``owned`` entries.

    :param owned: glob patterns of the top-level names the command writes (files or folders): a directory holding
        one of them but no manifest is refused by ``overwrite`` (see :func:`delete_recorded_outputs`).
    :param overwrite: delete the files the directory's manifest lists instead of refusing a non-empty directory
        (any other file is kept).
    :param keep: accept a non-empty directory as it is (resuming a run; the caller checks its files).
    :param field: the name the messages use for ``out`` (e.g. ``--out``).
    :param hint: what the refusal of a non-empty directory suggests.
    :return: ``out`` as a Path (it exists afterwards).
    :raises OutputError: if ``out`` is a file or cannot be created or written, or is not empty while neither
        ``overwrite`` nor ``keep`` is set (the message names its entries), or ``overwrite`` meets outputs without
        a manifest or a file the manifest does not list where the command writes one.
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{field} {str(path)!r} is a file, not a directory")
    if path.is_dir() and not keep:
        if overwrite:
            delete_recorded_outputs(path, owned, field)
        else:
            present = sorted(p for p in path.iterdir() if p.name != MANIFEST_FILE)
            if present:
                raise OutputError(f"{field} {str(path)!r} is not empty ({_names(present)}); {hint}")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"{field} {str(path)!r} cannot be created ({err.strerror or err})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise OutputError(f"{field} {str(path)!r} is not writable")
    return path


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

    Created after :func:`prepare_output_dir`, it takes the existing manifest (a resumed run's) and notes what
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
        new = {f for f in files - self._before_files if f != MANIFEST_FILE and not Path(f).name.endswith(".tmp")}
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

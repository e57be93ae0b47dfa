"""Output directories of the commands: checked and created before any work, old outputs refused or cleared.

Every command that writes into a directory the user names (``evaluate``, ``train``, ``paper``,
``plan-paper``, ``demo``) calls :func:`prepare_output_dir` before it simulates or trains anything:
an ``--out`` that is a file, or that cannot be created, fails at once. A command that must not mix
its files with an older run's (``evaluate``, ``train``) refuses a non-empty directory
(:class:`OutputError` naming what is there) unless asked to overwrite, which deletes the files the
command owns (a list of names) and leaves any other file alone.
"""

from __future__ import annotations

import fnmatch
import json
import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["OutputError", "owned_entries", "prepare_output_dir", "write_json_atomic"]

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


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def prepare_output_dir(
    out: str | os.PathLike[str],
    owned: Sequence[str] = (),
    overwrite: bool = False,
    keep: bool = False,
    field: str = "out",
    hint: str = OVERWRITE_HINT,
) -> Path:
    """Check and create the output directory ``out``; refuse a non-empty one, or delete the ``owned`` entries.

    :param owned: glob patterns of the top-level names the command writes (files or folders): what
        ``overwrite`` deletes. Other entries are never deleted.
    :param overwrite: delete the existing ``owned`` entries instead of refusing a non-empty directory.
    :param keep: accept a non-empty directory as it is (resuming a run; the caller checks its files).
    :param field: the name the messages use for ``out`` (e.g. ``--out``).
    :param hint: what the refusal of a non-empty directory suggests.
    :return: ``out`` as a Path (it exists afterwards).
    :raises OutputError: if ``out`` is a file or cannot be created or written, or is not empty while neither
        ``overwrite`` nor ``keep`` is set (the message names its entries).
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{field} {str(path)!r} is a file, not a directory")
    if path.is_dir() and not keep:
        if overwrite:
            try:
                for p in owned_entries(path, owned):
                    _remove(p)
            except OSError as err:
                raise OutputError(f"{field} {str(path)!r}: cannot delete an old output ({err})") from None
        else:
            present = sorted(path.iterdir())
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

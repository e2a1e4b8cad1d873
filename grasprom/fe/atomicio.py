"""Atomic file writes (temporary file, fsync, :func:`os.replace`) and the JSON encoding of the
FE data files (numpy values, paths, dataclasses and sets made serialisable).
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from pathlib import Path
from typing import Any


def json_default(obj: Any) -> Any:
    """Make numpy scalars/arrays, paths and dataclasses JSON-serialisable."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist"):  # numpy scalar or array
        return obj.tolist()
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serialisable")


FILE_MODE = 0o644
"""Permission bits of every file written here, whatever the umask (mkstemp creates 0600)."""


class AtomicWriteError(OSError):
    """Writing a file failed (disk full, read-only, permissions); nothing partial is left.

    Raised as ``AtomicWriteError(errno, strerror, path)``; :attr:`filename` is the target file
    (never the temporary one).
    """

    def __str__(self) -> str:
        return (
            f"cannot write {self.filename}: {self.strerror} "
            "(nothing was written; an earlier version of the file, if any, is unchanged)"
        )


def _write_all(fd: int, data: bytes) -> None:
    """Write every byte of ``data`` to the file descriptor ``fd`` (loops on short writes)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically, with mode 0644.

    The bytes go to a temporary file in the same directory, are fsync'ed, and the file is
    renamed over ``path`` with :func:`os.replace`; a reader (or a killed writer) sees either
    the old file or the complete new one. The file mode is :data:`FILE_MODE` (0644) whatever
    the umask.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; its directory must exist.
    data : bytes
        File content.

    Raises
    ------
    AtomicWriteError
        (an :class:`OSError`) naming ``path`` if the write fails, e.g. on a full disk; the
        temporary file is removed first.
    """
    path = Path(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            _write_all(fd, data)
            os.fsync(fd)
            os.fchmod(fd, FILE_MODE)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        if isinstance(exc, OSError) and not isinstance(exc, AtomicWriteError):
            raise AtomicWriteError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def atomic_write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """Atomically write ``obj`` as indented JSON (see :func:`atomic_write_bytes`)."""
    text = json.dumps(obj, indent=2, sort_keys=False, default=json_default, allow_nan=True)
    atomic_write_bytes(path, (text + "\n").encode())

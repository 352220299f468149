"""Atomic file writes: a crash or a full disk never leaves a half-written file under the final name.

The content goes to a temporary file in the same directory, which is moved onto the
final name with :func:`os.replace` (atomic on POSIX and Windows) only when the block
succeeds; on any error the temporary file is removed. Two processes writing the same
name both write whole files, and the last rename wins. Every writer of the project goes
through here (the FEA caches, :mod:`fea.store`, and the pipeline's readers and writers
via :mod:`pipeline.io.common`).
"""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_write", "atomic_path"]


def _create_tmp(path: Path, suffix: str) -> tuple[int, str]:
    """Exclusive new file next to ``path``. Unlike ``mkstemp`` (mode 0600) it is created
    with 0666 & ~umask, so the final file gets the permissions a plain ``open`` gives."""
    directory = path.parent
    for _ in range(100):
        tmp = directory / f".{path.name}.{secrets.token_hex(4)}{suffix}"
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666), str(tmp)
        except FileExistsError:
            continue
        except OSError as exc:
            raise ValueError(f"cannot write {path}: {exc.strerror or exc} (directory {directory})") from None
    raise ValueError(f"cannot write {path}: no free temporary name in {directory}")  # pragma: no cover


@contextmanager
def _moved_onto(tmp: str, path: Path) -> Iterator[None]:
    """Move ``tmp`` onto ``path`` when the block succeeds; remove it when the block fails."""
    try:
        yield
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


@contextmanager
def atomic_write(path: str | Path, mode: str = "w") -> Iterator:
    """Open a temporary file next to ``path``; on success move it onto ``path``.

    Parameters
    ----------
    path : str or Path
        Final destination.
    mode : {"w", "wb"}
        Text (UTF-8, ``\\n`` newlines) or binary.

    Raises
    ------
    ValueError
        If the directory does not exist or is not writable (names the path and reason).
    """
    path = Path(path)
    fd, tmp = _create_tmp(path, ".tmp")
    with _moved_onto(tmp, path):
        kw = {"encoding": "utf-8", "newline": "\n"} if "b" not in mode else {}
        with os.fdopen(fd, mode, **kw) as fh:
            yield fh


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Like :func:`atomic_write` for libraries that want a file *name* (xarray):
    yields a temporary path with the same suffix, moved onto ``path`` on success."""
    path = Path(path)
    fd, tmp = _create_tmp(path, f".tmp{path.suffix}")
    os.close(fd)
    with _moved_onto(tmp, path):
        yield Path(tmp)

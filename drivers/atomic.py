"""Atomic file writes: a file appears at its path whole, or the old one stays.

Each writer writes a temporary file in the target's folder (``.<name>.<12 hex>.tmp``: hidden, its
own, so two writers never share one), fsyncs it, renames it onto the target and fsyncs the folder.
On any failure the temporary file is removed and the target is left as it was.

- :func:`atomic_write`: a whole ``str`` or ``bytes`` at once.
- :func:`atomic_open`: a ``with`` block writing to a file object (``"w"`` text or ``"wb"`` binary).
- :func:`atomic_path`: a ``with`` block yielding the temporary path, for a file another library
  writes by name (h5py, ``savefig``, an event writer); ``keep_suffix`` for those that go by it.
- :class:`PendingFile`: the same when the writing spans a long-lived object's methods.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import IO, Any, BinaryIO, Literal, TextIO, overload

TEMPORARY_SUFFIX = ".tmp"


def temporary_path(path: str | Path, *, keep_suffix: bool = False) -> Path:
    """A fresh name beside ``path``: ``.<name>.<12 hex>.tmp`` (then ``path``'s suffix if ``keep_suffix``)."""
    path = Path(path)
    name = f".{path.name}.{uuid.uuid4().hex[:12]}{TEMPORARY_SUFFIX}"
    return path.with_name(name + (path.suffix if keep_suffix else ""))


def fsync_folder(folder: str | Path) -> None:
    """Force a folder's entries (a rename into it) to disk; a file system that cannot is let be."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse to fsync a folder; the rename itself is done
        pass
    finally:
        os.close(fd)


class PendingFile:
    """A file written under :attr:`tmp` and renamed onto :attr:`path` at :meth:`commit`.

    Args:
        path: the file's final path (its folder must exist).
        keep_suffix: end the temporary name with ``path``'s suffix (for writers that go by it).
    """

    def __init__(self, path: str | Path, *, keep_suffix: bool = False) -> None:
        self.path = Path(path)
        self.tmp = temporary_path(self.path, keep_suffix=keep_suffix)

    def commit(self) -> Path:
        """Fsync the temporary file, rename it onto :attr:`path`, fsync the folder; returns the path.

        Raises:
            OSError: the temporary file is missing or cannot be synced or renamed (it is removed then).
        """
        try:
            with open(self.tmp, "rb") as handle:
                os.fsync(handle.fileno())
            os.replace(self.tmp, self.path)
        except BaseException:
            self.discard()
            raise
        fsync_folder(self.path.parent)
        return self.path

    def discard(self) -> None:
        """Remove the temporary file (if any; never raises: a read-only folder refuses even that, and
        the error being handled is the one to tell); :attr:`path` is untouched."""
        with contextlib.suppress(OSError):
            self.tmp.unlink(missing_ok=True)


@contextmanager
def atomic_path(path: str | Path, *, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` for a library to write; renamed onto ``path`` when the
    block ends, removed if it raises (``path`` then untouched)."""
    pending = PendingFile(path, keep_suffix=keep_suffix)
    try:
        yield pending.tmp
    except OSError as exc:
        pending.discard()
        if exc.filename is not None and str(exc.filename) == str(pending.tmp):  # named by the file meant
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        pending.discard()
        raise
    pending.commit()


@overload
def atomic_open(
    path: str | Path,
    mode: Literal["w"] = ...,
    *,
    encoding: str = ...,
    newline: str | None = ...,
    permissions: int | None = ...,
) -> AbstractContextManager[TextIO]: ...
@overload
def atomic_open(
    path: str | Path,
    mode: Literal["wb"],
    *,
    encoding: str = ...,
    newline: str | None = ...,
    permissions: int | None = ...,
) -> AbstractContextManager[BinaryIO]: ...
def atomic_open(
    path: str | Path,
    mode: str = "w",
    *,
    encoding: str = "utf-8",
    newline: str | None = None,
    permissions: int | None = None,
) -> Any:
    """A ``with`` block writing a new file object for ``path`` (``mode`` ``"w"`` or ``"wb"``).

    Args:
        path: the file to write (its folder must exist).
        mode: ``"w"`` (text, ``encoding`` and ``newline`` as :func:`open`'s) or ``"wb"``.
        permissions: the file's mode bits (e.g. ``0o600``: never readable by others, even for an
            instant); default: as :func:`open` makes them (0666 less the umask).

    When the block ends the file is flushed, fsynced and renamed onto ``path``; when it raises the
    temporary file is removed and ``path`` is left as it was.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode {mode!r}: 'w' or 'wb'")
    return _atomic_open(Path(path), mode, encoding, newline, permissions)


@contextmanager
def _atomic_open(
    path: Path, mode: str, encoding: str, newline: str | None, permissions: int | None
) -> Iterator[IO[Any]]:
    pending = PendingFile(path)
    try:
        fd = os.open(pending.tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 if permissions is None else permissions)
    except OSError as exc:  # named by the file meant, not its hidden temporary name
        raise OSError(exc.errno, exc.strerror, str(path)) from exc
    try:
        if permissions is not None:
            os.fchmod(fd, permissions)  # whatever the umask
        handle: IO[Any] = (
            os.fdopen(fd, "wb") if mode == "wb" else os.fdopen(fd, "w", encoding=encoding, newline=newline)
        )
    except BaseException:
        os.close(fd)
        pending.discard()
        raise
    try:
        with handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(pending.tmp, path)
    except BaseException:
        pending.discard()
        raise
    fsync_folder(path.parent)


def atomic_write(
    path: str | Path, data: str | bytes, *, encoding: str = "utf-8", permissions: int | None = None
) -> Path:
    """Write ``data`` (text in ``encoding``, or bytes) to ``path`` atomically; returns the path.

    Args:
        permissions: the file's mode bits; default as :func:`open` makes them.

    Raises:
        OSError: it cannot be written (a full disk ...); ``path`` is as it was and no temporary file is left.
    """
    if isinstance(data, str):
        with atomic_open(path, "w", encoding=encoding, permissions=permissions) as text:
            text.write(data)
    else:
        with atomic_open(path, "wb", permissions=permissions) as binary:
            binary.write(data)
    return Path(path)

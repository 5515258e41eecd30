"""Files winder writes, written whole or not at all (ROS-free).

Every output of a command (a figure, a CSV export, a JSON table, a job file
tuned in place, a recovered bag) goes through this module:

* :func:`atomic_file` / :func:`write_text`: a temporary file in the target's
  directory, flushed and fsync'd, renamed over the target, the directory
  fsync'd: a reader sees the old file or the new one, never a part, whatever
  stops the writer (a full disk, a signal, a crash);
* :func:`new_directory`: the same for a directory of files (``winder export``,
  ``winder bag recover``): built under a hidden name beside it and renamed
  when complete;
* :func:`output_dir`: the directory an output goes into, made if missing.

An ``OSError`` on the way (an unwritable directory, a file where a
directory should be, no space left) becomes :class:`OutputError`: one line
naming the path the user gave and the reason, nothing left behind. It is
not an ``OSError`` on purpose, so that a command's handling of unreadable
*inputs* (bags, job files) never takes it for one: ``winder`` exits with
:data:`winder.cli.exits.EXIT_OUTPUT` on it.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from winder.errors import OutputError

__all__ = [
    "OutputError",
    "atomic_file",
    "check_writable",
    "fsync_path",
    "new_directory",
    "output_dir",
    "too_long_name",
    "write_text",
]


def _reason(exc: OSError) -> str:
    if exc.strerror:
        return exc.strerror
    text = str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


def _output_error(path: Path, exc: OSError, what: str = "cannot be written") -> OutputError:
    return OutputError(f"{path}: {what}: {_reason(exc)}")


def _ours(exc: OSError, *paths: Path | str | None) -> bool:
    """Whether the error is the writing's own: it names no file (a write, a
    flush, an fsync) or one of ours. An input read inside the block (a bag
    streamed into an export) that fails keeps its own error."""
    if exc.filename is None:
        return True
    names = {os.fspath(p) for p in paths if p is not None}
    return os.fspath(exc.filename) in names or any(
        os.fspath(exc.filename).startswith(n + os.sep) for n in names
    )


def fsync_path(path: Path) -> None:
    """fsync a file or a directory (a directory: so that a rename in it is on disk)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def output_dir(path: str | Path) -> Path:
    """The directory ``path``, made with its parents if missing; OutputError
    (one line) if it cannot be (a file in its way, no permission)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        in_way = _file_in_way(p)
        if in_way is not None:  # a file where the directory should be
            raise OutputError(f"{p}: cannot be made a directory: {in_way} is a file") from None
        raise OutputError(f"{p}: cannot be made a directory: {_reason(exc)}") from None
    return p


def _file_in_way(p: Path) -> Path | None:
    """The first of ``p`` and its parents that exists and is not a directory
    (None: none; a name too long to look up is none of them)."""
    for q in (p, *p.parents):
        try:
            if q.exists() and not q.is_dir():
                return q
        except OSError:  # ENAMETOOLONG and the like: that part cannot exist
            continue
    return None


#: the longest name of a file or directory (Linux NAME_MAX), bytes
NAME_MAX = 255


def too_long_name(path: str | Path) -> str | None:
    """The first name in ``path`` longer than :data:`NAME_MAX` bytes (no
    file system takes it: ENAMETOOLONG), else None."""
    return next((part for part in Path(path).parts if len(os.fsencode(part)) > NAME_MAX), None)


def check_writable(path: str | Path, *, directory: bool = False) -> Path:
    """OutputError (one line) unless the file (or, with ``directory``, the
    directory) ``path`` can be written later: the nearest part of it that
    exists is a directory this process can write into, probed by making and
    removing a directory there. Nothing is made or left behind: a command
    that writes its output after a long computation asks first."""
    p = Path(path)
    what = "cannot be made a directory" if directory else "cannot be written"
    if too_long_name(p) is not None:
        raise OutputError(f"{p}: {what}: a name in it is longer than {NAME_MAX} bytes")
    try:
        base = p if directory else (p.parent if str(p.parent) else Path("."))
        if not directory and p.is_dir():
            raise OutputError(f"{p}: cannot be written: it is a directory")
        probe = base
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if not probe.is_dir():
            raise OutputError(f"{p}: {what}: {probe} is a file")
        if probe != base:  # the rest is made later: each name of it must be one the system takes
            os.stat(base)
    except FileNotFoundError:
        pass
    except OSError as exc:  # a name too long, a loop of links
        raise _output_error(p, exc, what) from None
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".winder-probe-", dir=probe))
    except OSError as exc:
        raise _output_error(p, exc, what) from None
    return p


def _new_file_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


@contextlib.contextmanager
def atomic_file(path: str | Path, mode: str = "w", *, newline: str | None = None) -> Iterator[IO[Any]]:
    """An open file whose content replaces ``path`` when the block ends
    without an exception (temp file beside it, fsync, rename, fsync of the
    directory); on an exception the temp file is removed and ``path`` is as
    it was. A new file gets the mode a plain ``open`` would give it; an
    existing one keeps its mode and (where this process may give it) its
    owner. ``path`` itself is replaced: to write the file a symlink names,
    pass the resolved path. ``mode``: ``"w"`` or ``"wb"``."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_file: mode {mode!r} is not 'w' or 'wb'")
    target = Path(path)
    directory = output_dir(target.parent if str(target.parent) else ".")
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=directory)
    except OSError as exc:
        raise _output_error(target, exc) from None
    tmp = Path(tmp_name)
    try:
        try:
            st: os.stat_result | None = os.stat(target)
        except OSError:
            st = None
        os.fchmod(fd, _new_file_mode() if st is None else st.st_mode & 0o7777)
        if st is not None and hasattr(os, "fchown"):
            with contextlib.suppress(PermissionError):  # not ours to give away: the file becomes ours
                os.fchown(fd, st.st_uid, st.st_gid)
        kwargs: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8", "newline": newline}
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        fsync_path(directory)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if _ours(exc, tmp, target, directory):
            raise _output_error(target, exc) from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text(path: str | Path, text: str) -> Path:
    """``text`` into ``path``, atomically (:func:`atomic_file`)."""
    with atomic_file(path) as fh:
        fh.write(text)
    return Path(path)


@contextlib.contextmanager
def new_directory(path: str | Path, *, create: bool = True) -> Iterator[Path]:
    """A new directory ``path``, made whole or not at all: the block fills
    the directory yielded (beside ``path`` under a hidden name; with
    ``create=False`` it does not exist yet, for a writer that makes it
    itself), whose files are then fsync'd and which is renamed to ``path``.
    On an exception it is removed and ``path`` never appears. FileExistsError
    if ``path`` exists; OutputError (one line) if it cannot be written."""
    target = Path(path)
    if target.exists() or target.is_symlink():
        raise FileExistsError(f"{target}: already exists; choose a new directory")
    parent = output_dir(target.parent if str(target.parent) else ".")
    try:
        staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".part", dir=parent))
    except OSError as exc:
        raise _output_error(target, exc) from None
    work = staging / target.name
    try:
        if create:
            work.mkdir()
        yield work
        for root, _dirs, names in os.walk(work):
            for name in names:
                fd = os.open(os.path.join(root, name), os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
            fsync_path(Path(root))
        if target.exists() or target.is_symlink():  # made meanwhile: never replaced
            raise FileExistsError(f"{target}: already exists; choose a new directory")
        os.rename(work, target)
        fsync_path(parent)
    except FileExistsError:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    except OSError as exc:
        shutil.rmtree(staging, ignore_errors=True)
        if _ours(exc, staging, target, parent):
            raise _output_error(target, exc) from None
        raise
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    shutil.rmtree(staging, ignore_errors=True)

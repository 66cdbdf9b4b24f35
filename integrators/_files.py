"""Atomic file writes: the one way every package of the library writes a file."""

from __future__ import annotations

import contextlib
import glob
import os
import signal
import tempfile
import threading
from collections.abc import Iterator


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike) -> list[str]:
    """Remove the temporaries `.<name>.<pid>.*.tmp` that earlier writes of `path` left behind
    when their process was killed (SIGKILL cannot be caught); temporaries of live processes
    (a concurrent write) are kept. Returns the removed paths."""
    path = os.path.abspath(os.fspath(path))
    directory, name = os.path.split(path)
    removed = []
    for tmp in glob.glob(os.path.join(glob.escape(directory), f".{glob.escape(name)}.*.tmp")):
        pid = os.path.basename(tmp)[len(name) + 2 :].split(".", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            with contextlib.suppress(FileNotFoundError):
                os.remove(tmp)
                removed.append(tmp)
    return removed


@contextlib.contextmanager
def _sigterm_as_exit() -> Iterator[None]:
    """Within the block, SIGTERM raises `SystemExit` (so `finally` clauses clean up) instead of
    killing the process outright; the previous handler is restored after. An exit that Python
    swallows (raised while a finalizer or weakref callback ran: "Exception ignored in") is
    raised again when the block ends, and a second SIGTERM kills outright."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous not in (signal.SIG_DFL, None):  # the program handles SIGTERM itself: leave it
        yield
        return

    received: list[int] = []

    def handler(signum, frame):
        received.append(signum)
        signal.signal(signal.SIGTERM, previous)
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
    if received:  # the block ended normally: its exit was swallowed
        raise SystemExit(128 + received[0])


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yield a temporary path in `path`'s folder (created if missing) to write to; on success
    its data is flushed to disk and it is renamed over `path`, on any exception, Ctrl-C or
    SIGTERM it is removed. An interrupted write never leaves a half file nor clobbers an
    existing one; the temporaries of writes killed outright (SIGKILL) are removed by the next
    write of the same path (`remove_stale_temporaries`)."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as err:
        raise OSError(f"cannot create the folder {directory!r} to save {path!r}: {err.strerror}") from err
    if os.path.isdir(path):
        raise IsADirectoryError(f"cannot save to {path!r}: it is a folder; give a file name")
    remove_stale_temporaries(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.{os.getpid()}.", suffix=".tmp", dir=directory)
    os.close(fd)
    try:
        with _sigterm_as_exit():
            yield tmp
            with open(tmp, "rb+") as fh:  # data on disk before the rename makes it visible
                os.fsync(fh.fileno())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; a saved file is not
            os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write `text` to `path` atomically (see `atomic_path`)."""
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        f.write(text)


def open_hdf5(path: str | os.PathLike, expected: str):
    """`h5py.File(path, "r")`, or an error naming `path` and what was `expected` there:
    `FileNotFoundError`, `IsADirectoryError`, or `ValueError` for a file that is not readable
    HDF5 (a text file, a truncated or corrupt one)."""
    import h5py

    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such file: {path!r} (expected {expected})")
    if os.path.isdir(path):
        raise IsADirectoryError(f"path {path!r} is a folder; expected {expected}")
    try:
        return h5py.File(path, "r")
    except OSError as err:
        raise ValueError(
            f"path {path!r} is not a readable HDF5 file (corrupt, truncated or another format); expected {expected}"
        ) from err

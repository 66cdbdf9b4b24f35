"""Claims on a study's rows, so that processes running the same study into the same folder
(`python -m paper run W8 --full --out DIR`, started once per core) share its rows instead of
computing each one twice.

A process computes the row saved at `<row>.json` only while it holds an exclusive lock
(`fcntl.flock`) on `<row>.json.claim`; it unlocks and deletes the file when the row is saved or
its computation failed. The operating system releases the lock of a process that dies, so no
claim outlives its process (the file it leaves holds no lock: the next process takes it). A
lock taken on a file that was deleted meanwhile is dropped and taken again on the file now at
the path, and a process that wins a claim looks for the saved row before computing it
(`AbstractStudy`); rows are written atomically, so a race costs at worst a row computed twice,
never a wrong row. Where there is no `fcntl` (Windows) every claim succeeds and no file is
made: processes do not share rows.
"""

from __future__ import annotations

import contextlib
import os
import socket
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = ["claim", "holder", "release"]

#: This process's open claims: the claim file's path -> its locked descriptor.
_HELD: dict[Path, int] = {}


def _path(row: Path) -> Path:
    return Path(row).with_name(Path(row).name + ".claim")


def claim(row: Path) -> bool:
    """Claim the row to be saved at `row` for this process: True if it is this process's to
    compute (it holds the lock), False while another process holds it."""
    path = _path(row)
    if fcntl is None or path in _HELD:
        return True
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            same = os.fstat(fd).st_ino == os.stat(path).st_ino  # not a file deleted since it was opened
        except BlockingIOError:
            os.close(fd)
            return False
        except FileNotFoundError:
            same = False
        except BaseException:
            os.close(fd)
            raise
        if not same:  # released and deleted by its holder meanwhile: claim the file now at the path
            os.close(fd)
            continue
        try:
            os.ftruncate(fd, 0)  # who holds it, for a reader of the folder
            os.write(fd, f"{socket.gethostname()} {os.getpid()}\n".encode())
        except BaseException:
            os.close(fd)
            raise
        _HELD[path] = fd
        return True


def holder(row: Path) -> str | None:
    """Who holds the claim on `row` ("host pid"), `None` if no live process does."""
    path = _path(row)
    if path in _HELD:
        return f"{socket.gethostname()} {os.getpid()}"
    if fcntl is None:
        return None
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return os.read(fd, 256).decode(errors="replace").strip() or "another process"
        return None  # unlocked: its process has ended
    finally:
        os.close(fd)


def release(row: Path) -> None:
    """Delete and unlock this process's claim on `row` (nothing if it holds none)."""
    path = _path(row)
    fd = _HELD.pop(path, None)
    if fd is None:
        return
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    os.close(fd)  # closing the descriptor releases the lock

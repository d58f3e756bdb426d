"""The lock that gives an output folder to one run at a time.

A run that claims ``--out`` (:class:`vtoladapt.outputs.OutputDir`) holds an exclusive
``flock`` on :data:`LOCK_NAME` inside the folder until it ends; a second run into the same folder
(in this process or another) is refused in one line naming the holder. The file records who holds
it (process id, host, command, start time) for that message only: whether the lock is held is
decided by the kernel, never by the file's content.

Stale locks: the kernel releases an ``flock`` when the last descriptor of its holder closes, which
happens however the process ends (a crash, SIGKILL, a power-off of the process). A lock file left
by a dead run is therefore not held, and the next run takes it at once. Network file systems:
Linux emulates ``flock`` on NFS with byte-range locks (NLM), which are released when the holder's
process ends too; a file system without locks (some FUSE mounts) makes :func:`acquire` refuse
the folder rather than run unprotected.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Optional

LOCK_NAME = ".vtoladapt-lock"
PROBE_RETRIES = 5
"""Tries, 10 ms apart, before a held lock is taken to be a live run's (a probe holds it for microseconds)."""

try:  # POSIX; on a system without flock a folder is claimed without a lock (no second run refused)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None


class FolderInUse(Exception):
    """Another live run holds the folder's lock; ``holder`` describes it (may be empty)."""

    def __init__(self, holder: str):
        super().__init__(holder)
        self.holder = holder


def _describe(fd: int) -> str:
    """The holder recorded in the lock file, as "pid 123 on host, 'vtoladapt run', since ..."."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        doc = json.loads(os.read(fd, 4096).decode("utf-8"))
        return (f"pid {int(doc['pid'])} on {doc['host']}, 'vtoladapt {doc['command']}', since "
                f"{doc['started']}")
    except (OSError, ValueError, KeyError, TypeError):
        return "a process that has not yet recorded itself"


def _open_lock(folder: Path, create: bool) -> Optional[int]:
    flags = os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        return os.open(folder / LOCK_NAME, flags | (os.O_CREAT if create else 0), 0o644)
    except FileNotFoundError:
        return None


class FolderLock:
    """An acquired lock (:func:`acquire`); :meth:`release` removes the file and lets go."""

    def __init__(self, folder: Path, fd: int):
        self.folder = folder
        self._fd: Optional[int] = fd

    def release(self) -> None:
        """Remove the lock file (while still holding it, so no one takes a lock on a file about to
        vanish) and close it, which releases the lock. Idempotent."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            os.unlink(self.folder / LOCK_NAME)
        except OSError:
            pass
        os.close(fd)


def acquire(folder: Path, command: str) -> FolderLock:
    """Lock ``folder`` (it must exist) for this process; :class:`FolderInUse` if a live run holds it.

    The lock is taken on the file, then the file is checked to still be the one at the path: a
    holder that released it meanwhile unlinked it, and a lock on an unlinked file protects
    nothing, so that case starts over.
    """
    folder = Path(folder)
    busy = 0
    while True:
        fd = _open_lock(folder, create=True)
        if fcntl is None:
            return FolderLock(folder, fd)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _describe(fd)
            os.close(fd)
            busy += 1
            if busy < PROBE_RETRIES:  # perhaps only another run's probe (holder_if_locked), which lets go at once
                time.sleep(0.01)
                continue
            raise FolderInUse(holder) from None
        except OSError as exc:  # no locks on this file system: refuse rather than run unprotected
            os.close(fd)
            raise FolderInUse(f"the folder cannot be locked on this file system ({exc.strerror})") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(folder / LOCK_NAME, follow_symlinks=False).st_ino
        except OSError:
            same = False
        if not same:
            os.close(fd)
            continue
        doc = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
               "argv": sys.argv[1:], "started": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(doc).encode("utf-8"), 0)
        return FolderLock(folder, fd)


def holder_if_locked(folder: Path) -> Optional[str]:
    """The description of the live run holding ``folder``'s lock, or None (no file, or not held).
    Changes nothing on disk: the lock is probed and let go at once."""
    if fcntl is None:
        return None
    fd = _open_lock(Path(folder), create=False)
    if fd is None:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return _describe(fd)
        except OSError:
            return None
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)

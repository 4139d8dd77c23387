"""One writer per study folder: an exclusive lock, held for the writing verb's lifetime.

Rule: every verb that writes a study folder (its journal, its key file, its tables, recordings,
policies, exports, report) holds an exclusive `fcntl.flock` on `<folder>/.pairplay-lock` from
before it reads the journal until it ends (`protocol serve` for as long as it serves); a second
writer is refused at once (no waiting) in one line naming the folder and the holder, whose verb,
pid and start time the holder wrote into the lock file. The kernel drops the lock when the holder
ends, however it ends (SIGKILL too), so a lock is never stale, and the file stays, empty when nobody
writes (`protocol init` makes it; removing a locked file lets a third process lock a new one beside a
holder of the old). Read-only verbs
(`protocol status`) take no lock and run beside a writer. Why: two servers on one folder each kept
the journal in memory and gave the same id to two people (`p05,Carla` and `p05,Dieter` in the key
file), started one game twice, and undid a `participant delete` from a stale copy. flock, as
pairplay/livelock.py says why: not fcntl record locks.
"""

from __future__ import annotations

import fcntl
import os
import time
from pathlib import Path

LOCK_FILE = ".pairplay-lock"


class FolderBusy(Exception):
    """Another process writes the folder: `holder` says who, as it wrote it ("" if it had not yet)."""

    def __init__(self, holder: str):
        super().__init__(holder)
        self.holder = holder


def take(folder: str | Path, verb: str) -> int | None:
    """A descriptor holding `folder`'s writer lock (`release` it, or let the process end), after writing
    `verb`, the pid and the time into the lock file. FolderBusy if another process holds it. None if the
    folder cannot hold a lock file (read-only: the verb's own check refuses it in its words) or its file
    system has no locks (the verb goes on unlocked, as a recording does: livelock.hold)."""
    path = Path(folder) / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError:
        try:  # made by another user (a shared lab account): a read-only descriptor locks as well
            fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
        except OSError:
            return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise FolderBusy(holder(path)) from None
    except OSError:
        os.close(fd)
        return None
    stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{verb} (pid {os.getpid()}, since {stamp})\n".encode(), 0)
    except OSError:  # a read-only descriptor: the lock holds, the refusal cannot say who
        pass
    return fd


def holder(path: str | Path) -> str:
    """Who holds the lock of lock file `path`, as its holder wrote it; "" if it has not written yet."""
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace").strip().splitlines()[0]
    except (OSError, IndexError):
        return ""


def release(fd: int | None) -> None:
    """Empty the lock file and close a descriptor `take` gave (the lock goes with it); never raises. Empty: a
    folder nobody writes holds the same bytes before and after a verb that changed nothing (a refused one)."""
    if fd is None:
        return
    try:
        os.ftruncate(fd, 0)
    except OSError:
        pass
    try:
        os.close(fd)
    except OSError:
        pass

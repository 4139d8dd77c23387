"""A live recording is locked: any verb can tell it from a file left behind.

Rule: the recorder holds an exclusive `fcntl.flock` on its recording (a descriptor of
its own, `hold`, from the file's creation until its journal is gone) and the journal
writer on its journal (replay/wal.py), for as long as they write them; the kernel drops
the lock when the process ends, however it ends (SIGKILL, the OOM killer), so a file a
dead recorder left is never taken for live. `is_live(path)` tries a shared lock without
waiting: a file a live recorder holds is refused by every verb that would replace or
remove it, whatever `--force` says (`pairplay session --force` removed a running
session's recording, and that session then reported the second one's events as its
own). flock, not fcntl/lockf record locks: those belong to the process (closing any
descriptor of the file drops them) and are not seen by the process's own other
descriptors, so a session's recorder and a verb in the same process could not tell.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

LIVE = "is being recorded now by a live recorder"  # the words every refusal of a live file uses


def hold(path: str | Path, create: bool = False) -> int:
    """A descriptor of `path` holding its exclusive lock (close it to release). With `create` the
    file is created, and FileExistsError raised if it is there already (O_EXCL: of two recorders
    started at the same moment, one gets it). BlockingIOError if another holds the lock."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL if create else os.O_RDONLY
    fd = os.open(path, flags, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise
    except OSError:  # a file system without locks (ENOLCK, EOPNOTSUPP): record anyway, unlocked; only the
        pass  # live check cannot see this recording (a lock is what tells it, never what lets it be written)
    except BaseException:
        os.close(fd)
        raise
    return fd


def release(fd: int) -> None:
    """Close a descriptor `hold` gave (its lock goes with it); never raises."""
    try:
        os.close(fd)
    except OSError:
        pass


def is_live(path: str | Path) -> bool:
    """Whether a live recorder holds `path` (False if it is not there or cannot be opened)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)
    return False

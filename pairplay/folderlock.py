"""One writer per study folder: an exclusive lock, held for the writing verb's lifetime.

Rule: every verb that writes a study folder (its journal, its key file, its tables, recordings,
policies, exports, report) holds an exclusive `fcntl.flock` on `<folder>/.pairplay-lock` from
before it reads the journal until it ends (`protocol serve` for as long as it serves); a second
writer is refused in one line naming the folder and the holder, whose verb, pid and start time the
holder wrote into the lock file: at once when the holder is a long one (`protocol serve`, `protocol
pilot`: LONG_HOLDERS, which hold the folder for as long as they serve or play); a holder that writes
and ends in a moment (register, mark-invalid, report, export, delete, repair, a verb's journal line
of a copy) is first waited for, up to WAIT_S, the waiter saying on stderr for whom (`waiting`). Why
wait: two short commands that collide (a script's register beside an export) should both do what
they were asked; the second was refused at once, told to stop a holder that ended a moment later.
The kernel drops the lock when the holder
ends, however it ends (SIGKILL too), so a lock is never stale, and the file stays, empty when nobody
writes (`protocol init` makes it; removing a locked file lets a third process lock a new one beside a
holder of the old). An output's lock file (`take_file`, pairplay/outputs.py `hold`) is removed, safely: its holder
removes it while holding it (`release`'s `remove`), and every writer checks, once it holds a lock, that the name
still names its file, else opens the name again (docs/architecture.md, "Output locks"). Read-only verbs
(`protocol status`) take no lock and run beside a writer. A user's mistake a writer can see without the lock (a
study file edited since the study was created: the journal's first line, which nothing rewrites) is said before
it takes the lock: waiting first said "another pairplay writes this study folder", or waited for a register,
and then said the edit as a second line (replay/studydata.py `_created_unlocked`). Why: two servers on one folder each kept
the journal in memory and gave the same id to two people (`p05,Carla` and `p05,Dieter` in the key
file), started one game twice, and undid a `participant delete` from a stale copy. flock, as
pairplay/livelock.py says why: not fcntl record locks.

A wait ends at once on SIGINT/SIGTERM, in every verb: a KeyboardInterrupt unwinds it where the command's
handler raises one (cli/interrupts.py); where a verb stops on signals itself (services/bus.py
`stop_on_signals`: it only sets its stop event, and this wait is not on that event) `take` sees the signal
in pairplay/signals.py `stopping`, taken before the wait or during it, and raises KeyboardInterrupt itself
(the verb ends as interrupted: 130/143, its one line). Before, a `view` of a study's game stopped by
SIGTERM waited the whole 8 s to journal its partial copy, then said the folder was busy and exited 2.
"""

from __future__ import annotations

import fcntl
import os
import sys
import time
from pathlib import Path
from typing import Callable

from pairplay import signals, testpause

LOCK_FILE = ".pairplay-lock"
# verbs that hold a folder for minutes to hours: a writer beside them is refused at once (waiting is useless)
LONG_HOLDERS = ("protocol serve", "protocol pilot")
WAIT_S = 8.0  # how long a writer waits for a short holder: longer than a report's few seconds, short for a person
POLL_S = 0.05


class FolderBusy(Exception):
    """Another process writes the folder: `holder` says who, as it wrote it ("" if it had not yet)."""

    def __init__(self, holder: str):
        super().__init__(holder)
        self.holder = holder


def take(folder: str | Path, verb: str, wait: float = 0.0, waiting: Callable[[str], None] | None = None) -> int | None:
    """A descriptor holding `folder`'s writer lock (`release` it, or let the process end), after writing
    `verb`, the pid and the time into the lock file. FolderBusy if another process holds it: at once if that
    is a long holder (LONG_HOLDERS), else after waiting up to `wait` seconds for it to end, calling
    `waiting(holder)` once when it starts to wait for a holder that named itself (module rule). None if the
    folder cannot hold a lock file (read-only: the verb's own check refuses it in its words) or its file
    system has no locks (the verb goes on unlocked, as a recording does: livelock.hold)."""
    return take_file(Path(folder) / LOCK_FILE, verb, wait, waiting)


def take_file(path: str | Path, verb: str, wait: float = 0.0,
              waiting: Callable[[str], None] | None = None) -> int | None:
    """`take` of the lock file `path` itself (pairplay/outputs.py `hold`: one writer per output, its lock file
    kept outside the output, and removed by its holder as it lets go: `release`'s `remove`). The lock taken is
    the one of the file `path` names once it is held: a descriptor opened on a file its holder removed as we
    waited (or that was replaced) is locked alone, beside the next writer's, so it is opened again (`_names`)."""
    deadline, said, again = time.monotonic() + wait, False, False
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError:
            try:  # made by another user (a shared lab account): a read-only descriptor locks as well
                fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
            except OSError:
                return None
        if not again:  # (a test lands the holder's removal here: tests/test_output_locks.py)
            testpause.pause("lock-opened")
        try:
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    who = holder(path)  # "" for a moment after the holder took it, before it wrote its line
                    if is_long(who) or time.monotonic() >= deadline:
                        raise FolderBusy(who) from None
                    if signals.stopping:  # the verb is stopping on a signal (module rule): no wait for another
                        raise KeyboardInterrupt
                    if who and not said and waiting is not None:
                        waiting(who)
                        said = True
                    time.sleep(POLL_S)  # (a signal here unwinds: the descriptor is closed below)
        except OSError:  # no locks on this file system
            os.close(fd)
            return None
        except BaseException:  # FolderBusy, a KeyboardInterrupt while waiting
            os.close(fd)
            raise
        if _names(path, fd):
            break
        os.close(fd)  # removed by its holder as it let go (or replaced): the lock of another file; again
        again = True
    stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{verb} (pid {os.getpid()}, since {stamp})\n".encode(), 0)
    except OSError:  # a read-only descriptor: the lock holds, the refusal cannot say who
        pass
    return fd


def _names(path: str | Path, fd: int) -> bool:
    """Whether `path` names the file open as `fd` (same device and inode): False once it was removed or replaced.
    One that cannot be looked at otherwise is taken as named (its open worked: a retry would loop for ever)."""
    try:
        there, mine = os.stat(path), os.fstat(fd)
    except FileNotFoundError:
        return False
    except OSError:
        return True
    return (there.st_dev, there.st_ino) == (mine.st_dev, mine.st_ino)


def waiting_line(who: str, folder: str | Path) -> str:
    """What a writer says when it starts to wait for `who` (a holder's line) to end (`take`'s `waiting`)."""
    return f"waiting up to {WAIT_S:g} s for another pairplay that writes this study folder: {who} ({folder})"


def say_waiting(verb: str, folder: str | Path) -> Callable[[str], None]:
    """`take`'s `waiting` for the command `pairplay VERB`: its line on stderr (`folder` as the user gave it)."""
    from pairplay.errors import escaped  # (the folder as given, the holder's line as its lock file says it)
    return lambda who: print(f"pairplay {verb}: {escaped(waiting_line(who, folder))}", file=sys.stderr, flush=True)


def is_long(holder_line: str) -> bool:
    """Whether the holder that wrote `holder_line` is a long one (LONG_HOLDERS): never waited for."""
    return holder_line.startswith(LONG_HOLDERS)


def holder(path: str | Path) -> str:
    """Who holds the lock of lock file `path`, as its holder wrote it; "" if it has not written yet."""
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace").strip().splitlines()[0]
    except (OSError, IndexError):
        return ""


def release(fd: int | None, remove: str | Path | None = None) -> None:
    """Empty the lock file and close a descriptor `take` gave (the lock goes with it); never raises. Empty: a
    folder nobody writes holds the same bytes before and after a verb that changed nothing (a refused one).
    `remove`: the lock file `fd` holds, removed instead, while it is still held, so that lock files do not
    pile up (an output's: pairplay/outputs.py `hold`); a writer that opened it meanwhile finds, once it holds
    it, that the name is no longer its file's and opens the name again (`take_file`). Not a study folder's
    own (`take`): an older pairplay beside this one would hold the removed file unaware."""
    if fd is None:
        return
    try:
        if remove is not None and _names(remove, fd):
            os.unlink(remove)
        else:
            os.ftruncate(fd, 0)
    except OSError:
        pass
    try:
        os.close(fd)
    except OSError:
        pass

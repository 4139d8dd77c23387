"""A session's recordings beside one another, and which of them continues which.

Rule: a recorder restarted in place (docs/bus.md "Recording and crashes") never replaces the earlier file: it
writes `<stem>.<n>.mcap` beside it (`recordings_of` lists them, oldest first), copies the earlier file's readable
events first and records a RecordingGap whose `earlier_file` names it. The newest such file holds the whole
session; the earlier one, cut by the crash, is a part. Every verb reading the earlier file says so
(`continued_in`), before it suggests `pairplay recover`: following that advice made a third, partial copy of a
session already whole beside it (trial34 N).
"""

from __future__ import annotations

import glob
from pathlib import Path

from pairplay.errors import InputError


def recordings_of(path: Path) -> list[Path]:
    """A session's existing recordings: `path` and every `<stem>.<k>.mcap` beside it (k = 1, 2 ...),
    in that order (gaps in k allowed: any of them makes the session id taken)."""
    path = Path(path)
    numbered = []
    if path.parent.is_dir():
        for p in path.parent.glob(f"{glob.escape(path.stem)}.*{glob.escape(path.suffix)}"):
            k = p.name[len(path.stem) + 1:len(p.name) - len(path.suffix)]
            if k.isascii() and k.isdigit():
                numbered.append((int(k), p))
    return ([path] if path.exists() else []) + [p for _, p in sorted(numbered)]


def continued_in(path: str | Path) -> Path | None:
    """The restarted recorder's file beside `path` that continues it (its RecordingGap's `earlier_file` is `path`'s
    name), the newest if several (each continues the one before); None if there is none. Only the files named
    `<stem>.<k>.mcap` after `path`'s own stem are read, and of each only its RecordingGap events."""
    from pairplay.replay.reader import read_any_log

    path = Path(path)
    found, earlier = None, path.name
    for later in recordings_of(path)[1:] if path.exists() else []:
        try:
            gaps = read_any_log(later, only=frozenset({"RecordingGap"})).of("RecordingGap")
        except (InputError, OSError):
            continue
        if any(g.earlier_file == earlier for g in gaps):
            found, earlier = later, later.name
    return found

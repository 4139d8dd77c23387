"""Is this file a recording at all? The check every verb makes before it reads one.

Rule: a path given as a recording must name a readable, non-empty file that
starts with MCAP's magic bytes (MCAP specification: the file begins with
0x89 "MCAP0" CR LF); anything else is an `InputError` naming the path, raised
before anything is written. How much of a real MCAP file is intact is the
reader's business (reader.py); this only keeps what is not MCAP at all from
being read as an empty recording.
"""

from __future__ import annotations

from pathlib import Path

from pairplay.errors import InputError

MCAP_MAGIC = b"\x89MCAP0\r\n"


def check_recording(path: str | Path) -> Path:
    """`path` as a Path if it can be read as an MCAP recording; InputError saying why not."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such recording", path)
    if path.is_dir():
        raise InputError("a folder, not a recording (give the .mcap files)", path)
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except OSError as err:
        raise InputError(f"cannot read the recording: {err.strerror}", path) from None
    if not head:
        raise InputError("empty file (0 bytes), not a recording", path)
    if head != MCAP_MAGIC:
        raise InputError("not an MCAP recording: it does not start with MCAP's magic bytes", path)
    return path

"""Every file a user names for pairplay to read is a regular file (or a folder where a verb takes one).

Rule: before an input is opened, what stands at its path is judged (`refusal`): a named pipe (FIFO), a character
or block device (/dev/null, /dev/zero), a socket is refused in one line naming the path and what it is, exit 2,
in every verb alike. Why before: opening a FIFO for reading blocks until a writer comes, so `rebuild`, `replay
--verify`, `recover` and `combine` given one waited silently until a signal (a new user's trial); a device reads
as endless zeros or as nothing, never as a recording. A symbolic link is followed and what it names is judged: a
link to a regular file is that file (links are how recordings are shared), and /dev/stdin, /dev/fd/N (links to a
pipe, a terminal) are refused as what they name. A dangling link, or nothing there, is left to the reader, which
says "no such file" in its own words. A file of this kind found by scanning a folder given as input (`combine
rebuilt/`'s *.json, a study folder's recordings) is refused alike, by the reader of that file: a pipe named
x.json in a folder of policies is a mistake to say, not a file to skip silently.

Outputs have their own rule (pairplay/outputs.py `check_kind`: nothing but a regular file is replaced, links
not followed); both name a kind in `outputs.special_kind`'s words.
"""

from __future__ import annotations

import os
from pathlib import Path

from pairplay.errors import InputError
from pairplay.outputs import special_kind

READS = "pairplay reads recordings, policies, grids, study files, keys and configs from regular files"


def refusal(path: str | Path) -> str:
    """Why `path` may not be read as an input file ("is a named pipe (FIFO), not a regular file; pairplay reads
    ... from regular files"), judged without opening it; "" if it may (a regular file, a folder, a link to
    either, or nothing there: the reader says each in its words)."""
    kind = special_kind(path, follow=True)
    if kind is None:
        return ""
    if os.path.islink(path):  # /dev/stdin: say that the name is a link, and what it names
        kind = f"a symbolic link to {kind}"
    return f"is {kind}, not a regular file; {READS}"


def check_input(path: str | Path, error: type[Exception] = InputError) -> None:
    """Raise `error` if `path` may not be read (`refusal`): an InputError(what, path) by default; any other
    error kind (a file kind's own: CalibrationError, GridError...) gets one message, "<path>: <what>", as its
    other refusals are worded."""
    said = refusal(path)
    if not said:
        return
    if error is InputError:
        raise InputError(said, path)
    raise error(f"{path}: {said}")


def check_option_file(path: str | Path, option: str) -> Path:
    """`path`, which `option` names (`--certfile`: a file handed to a library, read when it starts), as a Path if
    it names a regular file (or a link to one); an InputError naming the option and the path if nothing, a folder
    or anything else stands there (`refusal`), said before anything starts."""
    where = f"{option} {path}"
    if said := refusal(path):
        raise InputError(said, where)
    if os.path.isdir(path):
        raise InputError("a folder, not a file: give the path of one file", where)
    if not os.path.isfile(path):
        raise InputError("no such file", where)
    return Path(path)

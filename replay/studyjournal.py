"""Reading a study's journal (journal.jsonl) line by line, and setting aside the last line a crash cut.

Rule: a journal line that cannot be read is refused in one line naming the file, the line and what to do,
never skipped (every verb goes from the fold of all of it). A LAST line without its end of line that does
not read is what a crash (a kill, a power cut, a full disk) leaves in the middle of an append: the
refusal says so and names `pairplay protocol repair STUDY`, which moves those bytes, unchanged, into a
file beside the journal (`journal.jsonl.torn-<UTC time>`, never over another) and keeps every whole line:
nothing is deleted, and the study goes on from the last whole line (a game whose end was the torn line
is journaled from its recording by the next `serve`, `pilot` or `report`, as after any stop). Any other
line that does not read (a hand edit, a damaged disk) is not a crash's: repair refuses it and changes
nothing; the refusal says to put back a backup or correct that line. Before, both said msgspec's "Input
data was truncated" and no advice, and blocked every verb of the study.

A journal starts with the StudyCreated line `protocol init` writes. One that does not (empty, 0 bytes, or its
first lines lost) in a folder that holds a study's data was taken as a new study: nobody registered, p01 given
again and participants.csv rewritten down to it. Every verb, repair too, refuses it: put back a backup.

A torn line set aside that was a registration names the id it gave (`torn_registration`): the key file may
hold that id's line already (it is written first), so the id is never given again (replay/studydata.py
`ids_on_record`), and repair says so.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

import msgspec

from pairplay.errors import command_word
from pairplay.inputs import refusal
from pairplay.numbers import counted
from pairplay.outputs import write_bytes
from pairplay.schemas import journal as j
from pairplay.schemas.jsonfile import in_words

TORN = ".torn"  # journal.jsonl.torn-<time>: a torn last line set aside by `protocol repair`


class JournalDamaged(ValueError):
    """A line of the journal cannot be read: `line` its number (from 1), `torn` whether it is the last line a
    crash cut in the middle of an append (repair sets it aside), the message says it in one line."""

    def __init__(self, message: str, line: int, torn: bool):
        super().__init__(message)
        self.line, self.torn = line, torn


def _why(err: Exception, line: bytes) -> str:
    """Why a journal line does not read, in the file's words (schemas/jsonfile.py in_words, the line's
    column): an event type this pairplay does not know is a newer pairplay's."""
    said = str(err)
    if said.startswith("Invalid value ") and said.endswith("- at `$.event`"):
        return (f"event {said.removeprefix('Invalid value ').removesuffix(' - at `$.event`')} is not one this "
                "pairplay knows (written by a newer pairplay? upgrade pairplay)")
    return in_words(err, data=line.rstrip(b"\n")).replace("at line 1, column", "at column")


def _lines(data: bytes) -> list[bytes]:
    """The lines of journal bytes, each with its end of line but a last one without."""
    parts = data.split(b"\n")
    return [p + b"\n" for p in parts[:-1]] + ([parts[-1]] if parts[-1] else [])


def events_of(data: bytes, named: Path, folder: Path, repairing: bool = False) -> list[j.JournalEvent]:
    """The events of journal bytes `data` (`named` the journal as the user gave it, `folder` the study folder
    as given, for the repair's command); JournalDamaged for a line that does not read (module rule).
    `repairing`: said by `protocol repair`, which changes nothing then."""
    lines = _lines(data)
    events = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            events.append(j.decode_line(line))
        except (msgspec.DecodeError, msgspec.ValidationError) as err:
            if n == len(lines) and not line.endswith(b"\n") and not repairing:
                raise JournalDamaged(
                    f"{named}:{n}: its last line is cut short ({counted(len(line), 'byte')}, no end of line): "
                    "pairplay stopped while it wrote it (a crash, a power cut, a full disk); `pairplay protocol "
                    f"repair {command_word(folder)}` sets it aside in a file beside the journal and keeps every whole line",
                    n, True) from None
            raise JournalDamaged(
                f"{named}:{n}: {_why(err, line)}; not a crash's cut last line"
                + (", so `protocol repair` changed nothing" if repairing else "")
                + f": put back a backup of {named.name}, or correct line {n} by hand (one JSON object a line, "
                "docs/study.md)", n, False) from None
    if not events or not isinstance(events[0], j.StudyCreated):
        what = ("it is empty" if not events else
                f"its first line is a {type(events[0]).__name__}, not the StudyCreated line `protocol init` writes")
        raise JournalDamaged(
            f"{named}: the journal lost its beginning ({what}); read so, the study would start again (ids given "
            f"again, participants.csv rewritten), so every verb refuses it"
            + (" and `protocol repair` changed nothing" if repairing else "")
            + f": put back a backup of {named.name}", 1, False)
    return events


def numbered(data: bytes) -> list[tuple[int, j.JournalEvent]]:
    """(line number from 1, event) of each line of journal bytes that reads, numbered as `events_of` names a line
    (a refusal that names the line a problem is on: replay/studydata.py `fold_problems`)."""
    found = []
    for n, line in enumerate(_lines(data), 1):
        if line.strip():
            try:
                found.append((n, j.decode_line(line)))
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue  # events_of says it
    return found


_REGISTERED = re.compile(rb'"event"\s*:\s*"ParticipantRegistered".*?"participant"\s*:\s*"([^"\\]+)"')


def torn_registration(tail: bytes) -> str:
    """The participant id a torn line registered, if what is left of it says so; "" if not (another event,
    or cut before its id)."""
    m = _REGISTERED.search(tail)
    return m.group(1).decode("utf-8", "replace") if m else ""


_EVENT = re.compile(rb'^\s*\{\s*"event"\s*:\s*"([A-Za-z]+)"')
_PARTICIPANT = re.compile(rb'"participant"\s*:\s*"([^"\\]+)"')


def torn_event(tail: bytes) -> tuple[str, str]:
    """(the event type, the participant) a torn line was, as far as what is left of it says ("" for what it
    does not say): `repair` names what it set aside (a person's ConsentGiven: to be recorded again)."""
    kind, pid = _EVENT.search(tail), _PARTICIPANT.search(tail)
    return (kind.group(1).decode() if kind else "", pid.group(1).decode("utf-8", "replace") if pid else "")


def torn_ids(journal: Path) -> set[str]:
    """The ids registered by torn lines `repair` set aside beside `journal` (module rule)."""
    ids = set()
    for aside in journal.parent.glob(f"{journal.name}{TORN}-*"):
        if refusal(aside):  # never opened (a pipe blocked `register`: pairplay/inputs.py); one holds no id
            continue
        try:
            pid = torn_registration(aside.read_bytes())
        except OSError:
            continue
        if pid:
            ids.add(pid)
    return ids


@dataclass(frozen=True)
class Repaired:
    """What `repair` did: `aside` the file the torn line went to (None: nothing was torn), its `torn` bytes,
    the whole lines `kept`, and `newline` if the last line was whole but for its end of line (added)."""

    aside: Path | None
    torn: bytes
    kept: int
    newline: bool = False


def repair(path: Path, named: Path, folder: Path) -> Repaired:
    """Set aside the journal's torn last line (module rule), the caller holding the folder's writer lock.
    JournalDamaged for a damaged line that is not a torn last line (nothing is changed)."""
    from .studydata import atomic_write  # (studydata imports this module)

    data = path.read_bytes()
    cut = data.rfind(b"\n") + 1
    head, tail = data[:cut], data[cut:]
    whole = events_of(head, named, folder, repairing=True)  # every line before: a damaged one is not the crash's
    if not tail.strip():
        if tail:  # blanks after the last line: no event lost, nothing to set aside
            atomic_write(path, head)
        return Repaired(None, b"", len(whole))
    try:
        j.decode_line(tail)
    except (msgspec.DecodeError, msgspec.ValidationError):
        pass
    else:  # a whole event but for its end of line: the next append would have run on into it
        atomic_write(path, data + b"\n")
        return Repaired(None, b"", len(whole) + 1, newline=True)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    aside, n = path.with_name(f"{path.name}{TORN}-{stamp}"), 1
    while aside.exists() or aside.is_symlink():  # never over another: an earlier repair's stays
        n += 1
        aside = path.with_name(f"{path.name}{TORN}-{stamp}-{n}")
    write_bytes(aside, tail)
    atomic_write(path, head)  # after the copy is safe: a crash between leaves both, nothing lost
    return Repaired(aside, tail, len(whole))

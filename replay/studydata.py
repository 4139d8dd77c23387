"""A study's data folder: the plan, the journal, participants, export and deletion.

Rule: one folder per study, readable without pairplay:
  study.toml                   the study definition (schemas/study.py), as given
  journal.jsonl                the study's events, one JSON object a line (schemas/journal.py)
  recordings/<session>.mcap    one MCAP file per game: every event, questionnaire answers included
  policies/<session>.policy.json   the policy each game learned (rebuilt from its recording)
  merged/<phase>-bias.policy.json  the bias policy of a pi-reuse phase, with the rule of each state
  merged/<phase>-bias-v<n>.policy.json  the phase's bias policy combined again after a game it took was marked
                               invalid (replay/biases.py); the earlier file stays, for the games played on it
  participants.csv, sessions.csv, answers.csv   tables derived from the above (`write_tables`)
  exports/<id>.zip             a participant's data, on request (`export_participant`): the only place
                               inside the folder an export goes (a copy elsewhere in it survived the
                               deletion); one outside the folder is journaled (ParticipantExported)
Every other copy of a participant's data pairplay writes (a verb's output made of the folder's files, beyond
the places above: replay/copies.py) is journaled too (CopyWritten, with the SHA-256 of what was written), and
the deletion erases each journaled copy that is still pairplay's own, unchanged file, and names the others
(changed since, or gone from there: `copies_of`, `_settle`).
The state (who is registered, which game is next, what is done) is the fold of
the journal (`StudyState`), which must fold into consistent tables before anything is written (`check_folds`: a
registration removed by hand is refused, not written on); the plan (`plan`) follows from the study file and
that state. How a game ended and its policy come from its recording
(`game_end`); what a stopped server could not journal (the policy of a game
completed before a signal cut its questionnaire, the end of a game whose
process went while reading it back) is journaled later, from the recordings,
by `build_missing_policies`. A game's recording stands for the game only if it is that game's
(`not_this_game`: its SessionStarted against the journal and the plan): another session written over
it (`session --force --session <its id>`) gives the game no picks, answers or policy. Participants are pseudonymous ids (p01, p02, ...): a name given at
registration goes only to the key file, which must lie outside the study folder,
and is refused when the study has no key file.
A persona that played a participant's games (a rehearsal) is named as what it is
wherever a participant is named for people to read (`user_names`, `named`, the
plan's labels; the tables' `scripted` column): a scripted game's session runs as
`human:<id>` (the plan's participant), so its policy file, a combination's users
and rules said `human:p01` of a persona (the report's bias section, the console).
"""

from __future__ import annotations

import contextlib
import csv
import fnmatch
import hashlib
import io
import logging
import os
import re
import secrets
import threading
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import msgspec

from pairplay import __version__, csvcell, folderlock, signals, testpause
from pairplay.errors import InputError, UserError, command_word, escaped, folded, unshowable
from pairplay.inputs import refusal
from pairplay.livelock import LIVE, is_live
from pairplay.outputs import (OutputError, check_output, check_places, manifest_name, output_file, read_manifest,
                              remove_written, set_aside_of, special_kind, write_manifest)
from pairplay.schemas import journal as j
from pairplay.schemas.trust import MAX_REASON
from pairplay.schemas.jsonfile import in_words, without_bom
from pairplay.schemas.policy import encode_policy, read_policy, write_policy
from pairplay.schemas.study import CONSENT_FORM_RULE, STUDY_FILE, Study, StudyFileError, consent_form_ok, load_study
from pairplay.numbers import counted

from .cutgame import CUT_BEFORE_END, CutEnd, cut_end
from .fold import Summed
from . import biases, studyjournal
from .check import RoundWatch
from .studyroot import JOURNAL  # noqa: F401  (one name: a study folder's journal; re-exported)
from .reader import events_of, fold_log
from .rebuild import Rebuilt, output_paths, rebuild_recording
from .recover import default_output, journal_more
from .wal import wal_path
from pairplay.schemas.nesting import json_decode
from pairplay.schemas.repeated import refuse_repeated

SETTINGS = "settings.json"  # and JOURNAL (replay/studyroot.py), STUDY_FILE (schemas/study.py)
# what `pairplay report` writes in <folder>/report (report/human.py), and its manifest: here, below the report,
# since a participant's deletion removes those files (and only those: a user's notes.md there stays)
REPORT_OUTPUTS = ("picks.csv", "games.png", "phases.png", "users-*.png", "merged.png", "attention.csv",
                  "questionnaire.csv", "report.md")
REPORT_MANIFEST = manifest_name("report")
# the study folder's own files (`pairplay protocol`), listed in its manifest, written again from the journal at each
# of its lines (`write_folder_manifest`): another verb's folder output is refused any of them (outputs.check_theirs:
# `rebuild --out STUDY/policies --force` replaced a game's policy; `study --out STUDY --force` took the folder)
PROTOCOL_MANIFEST = manifest_name("protocol")
TABLES = ("participants.csv", "sessions.csv", "answers.csv")
# records of given ids (`StudyData.records_of_ids`) whose words a note picks out
NEVER_RECORDED = "stopped before its recording began"  # the reason of a game a signal stopped that early
KEY_RECORD, TORN_RECORD = "the key file", "a torn journal line set aside"
SUBFOLDERS = {"recordings": ".mcap", "policies": ".policy.json", "merged": ".policy.json"}  # and the files each holds


# how long before its study folder was made a consent may have been signed (`record_consent`): paper forms signed at
# recruitment, weeks before the folder, are taken; a year's typo (2016 for 2026) is not
CONSENT_BEFORE_STUDY_NS = 365 * 24 * 3600 * 10**9


class StudyDataError(UserError, ValueError):
    """A request the study folder cannot satisfy: what, and where (a file, a folder, an option) as every
    refusal says it, `what (where)` (pairplay/errors.py UserError: it said `<path> exists (use --force to
    replace it)`, `key file <path>: <why>`, `<folder>: already a study folder`, unlike every other verb)."""


@contextlib.contextmanager
def journaled_or_removed(path: Path):
    """The block that journals `path`, a file of the study folder just written (a game's policy, a bias policy):
    the file first, then its line, as every writer of the folder orders them (replay/copies.py `journal_each`);
    a line that cannot be written (the journal refused, a signal) removes the file, so the folder holds no file
    its journal does not know (a participant's deletion reads the journal: `files_of`, `merged_using`). The block
    calls `done()` on what it yields right after the line is written, under pairplay/signals.py `held` there: a
    signal then is delivered after it and removes nothing. A process killed between the two (SIGKILL) leaves the
    file: its writer replaces it on its next run (build_missing_policies writes with force; StudyRunner.combine
    removes what services/biasfile.py proves a killed combination's, and refuses any other file at its place)
    and a deletion erases a game's (`files_of`: named after it)."""
    state = {"journaled": False}

    @contextlib.contextmanager
    def line():
        with signals.held():
            yield
            state["journaled"] = True
    try:
        yield line
    except BaseException:
        if not state["journaled"]:
            path.unlink(missing_ok=True)
        raise


def atomic_write(path: Path, data: bytes, force: bool = True) -> None:
    """Write `data` to `path` through a temporary file renamed when complete (pairplay/outputs.py
    `output_file`: removed on any failure, with the folders made for it; a refusal names `path`, not the
    temporary file: `participant export -o /proc/p.zip` said "(/proc/.p.zip.<pid>.tmp)"). `force`: the
    study folder's own files are replaced; a user's output (an export's -o) only with their --force."""
    with output_file(path, "wb", force=force) as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


KEY_FILE_MODE, KEY_FOLDER_MODE = 0o600, 0o700  # the one file that links ids to names: its owner only
# the first line `protocol init` writes in a key file: a plain CSV header whose third column names the study that
# owns the file (`StudyData.key_owner`), so that a second init refuses it while it holds no participant yet
# (trial29 F9: an empty key file was taken by two studies)
KEY_HEADER = ("id", "name", "study")


def key_header(owner: str) -> list[str]:
    """The key file's header line of the study `owner` (`StudyData.key_owner`): `id,name,study <owner>`."""
    return [KEY_HEADER[0], KEY_HEADER[1], f"{KEY_HEADER[2]} {owner}"]


def is_key_header(row: list[str]) -> bool:
    """Whether a key file's first line is the header `protocol init` wrote (`key_header`)."""
    return len(row) >= 3 and tuple(row[:2]) == KEY_HEADER[:2] and row[2].split(" ", 1)[0] == KEY_HEADER[2]


def other_work(folder: Path) -> list[str]:
    """What the folder `folder` holds that makes it no place for a new study (`StudyData.create`), sorted, a folder
    named with a `/`: every entry but a hidden one (`.DS_Store`, `.git`: a file manager's or the user's own, not
    work), though another pairplay verb's manifest (`.pairplay-*.manifest`) is work (that verb's outputs are
    there), and but what a `create` cut short leaves (the study file, the settings, its folders empty), which it
    writes again. Empty if `folder` is missing or is not a folder (check_places says that)."""
    if not folder.is_dir():
        return []

    def work(p: Path) -> bool:
        if p.name.startswith("."):
            return fnmatch.fnmatchcase(p.name, manifest_name("*"))
        if p.name in (STUDY_FILE, SETTINGS):
            return False
        return not (p.name in SUBFOLDERS and p.is_dir() and not p.is_symlink() and not any(p.iterdir()))
    return sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir() if work(p))


def study_folder_holding(path: Path) -> Path | None:
    """The people's study folder `path` lies in (a folder above it with the study folder's manifest, or its
    journal and study file: one made before the manifest), None if none. Real names never sit in one (trial29 F8:
    a key file in ANOTHER study's folder, even its recordings/, was taken: names beside its pseudonymous data)."""
    for folder in Path(path).resolve().parents:
        if (folder / PROTOCOL_MANIFEST).is_file() or ((folder / JOURNAL).is_file() and (folder / STUDY_FILE).is_file()):
            return folder
    return None


def open_key_file(path: Path):
    """The key file for appending, created (with the folder it is in) readable by its owner only, and
    made so if it was not (a key file written 0644 by pairplay <= 0.3, or by hand). `StudyDataError`
    if it cannot be made (the path says where), or if it is inside a people's study folder
    (`study_folder_holding`): every writer of real names opens it here."""
    if path.is_dir():  # it said the system's "Is a directory"
        raise StudyDataError("a folder, not a key file: give the path of a CSV file (made if missing)", path)
    inside = study_folder_holding(path)
    if inside is not None:
        raise StudyDataError(f"is inside the study folder {inside}: a key file of real names never lies in a study "
                             "folder, this study's or another's (they are shared and archived as plain files); give "
                             "a path outside every study folder", path)
    kind = special_kind(path, follow=True)  # a link to the user's key file is theirs to keep; appended through
    if kind is not None:  # a named pipe: `protocol init --key-file FIFO` waited for ever; a device took the names
        raise StudyDataError(f"is {kind}, not a key file: give the path of a regular CSV file (made if missing)", path)
    try:
        path.parent.mkdir(mode=KEY_FOLDER_MODE, parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, KEY_FILE_MODE)
        os.fchmod(fd, KEY_FILE_MODE)
    except OSError as err:
        raise StudyDataError(f"cannot write the key file there: {err.strerror or err}", path) from None
    return open(fd, "a", encoding="utf-8", newline="")


def key_file_rows(path: Path, header: bool = False) -> list[list[str]]:
    """The key file's lines as csv reads them (a quoted cell may hold a CR), blank ones left out: `id,name,study`
    (`StudyData.key_owner`; `id,name` from an older pairplay, whose study is not said), after the header line
    `protocol init` writes (KEY_HEADER; left out unless `header`). StudyDataError if it is not there or cannot be read."""
    if said := refusal(path):  # before opening: a pipe blocked (pairplay/inputs.py)
        raise StudyDataError(said, path)
    try:
        with open(path, encoding="utf-8", newline="") as f:
            rows = [r for r in csv.reader(f) if r]
            return rows[1:] if rows and is_key_header(rows[0]) and not header else rows
    except FileNotFoundError:
        raise StudyDataError("the key file is not there (an unmounted drive?): the ids it holds cannot be "
                             "checked, and one of them would be given again; make it reachable first", path) from None
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise StudyDataError(f"cannot read the key file: {getattr(err, 'strerror', None) or err}", path) from None


@dataclass
class Game:
    session: str
    participant: str
    phase: str
    game: int
    recording: str
    bias: str = ""
    ended: j.GameEnded | None = None
    invalid: str = ""
    invalid_ns: int = 0  # when it was marked invalid (its SessionMarkedInvalid's time)
    paused: bool = False
    scripted: str = ""  # the persona that played instead of a person (a rehearsal); "" for a person

    @property
    def valid_complete(self) -> bool:
        return self.ended is not None and self.ended.outcome == "completed" and not self.invalid


@dataclass
class StudyState:
    """The fold of a journal."""
    created: j.StudyCreated | None = None
    participants: dict[str, j.ParticipantRegistered] = field(default_factory=dict)
    consent: dict[str, j.ConsentGiven] = field(default_factory=dict)  # participant -> their last consent recorded
    consents: dict[str, dict[str, j.ConsentGiven]] = field(default_factory=dict)  # participant -> form -> its consent
    # the consent form from the last ConsentFormChanged (an ethics amendment); None: the study file's
    consent_form: str | None = None
    forms_changed: list[str] = field(default_factory=list)  # every ConsentFormChanged's form, in order
    games: dict[str, Game] = field(default_factory=dict)
    combined: dict[str, j.BiasCombined] = field(default_factory=dict)  # phase -> its current bias (its last)
    # every combination, in order: one made again (a game it took marked invalid since) keeps the earlier one's
    # file and line, for the games played on it (replay/biases.py)
    combinations: list[j.BiasCombined] = field(default_factory=list)
    deletions: list[j.ParticipantDeleted] = field(default_factory=list)
    # the bias policies made with a deleted participant's game marked invalid since: kept by their deletion
    # without the id (replay/biases.py flags them as it flags one made with a game still in the journal)
    flaws_kept: list[j.FlawKept] = field(default_factory=list)
    next_number: int = 1
    # ids given out: a registration left in the journal, or a deletion (it removed its one registration line
    # and keeps no id). Ids are given in order, so the next is one past both this count and the highest left.
    ids_given: int = 0
    # every id a line names (a registration, a game, an export, a copy's participants, a combination's users):
    # a line whose registration was removed by hand still shows the id was given (StudyData.ids_on_record)
    named: set[str] = field(default_factory=set)

    def evolve(self, e: j.JournalEvent) -> None:
        self.named |= ids_named_by(e)
        if isinstance(e, j.StudyCreated):
            self.created = e
        elif isinstance(e, j.ParticipantRegistered):
            self.participants[e.participant] = e
            self.ids_given += 1
            number = int(e.participant[1:]) if e.participant[1:].isdigit() else 0
            self.next_number = max(self.next_number, number + 1, self.ids_given + 1)
        elif isinstance(e, j.ConsentGiven):
            self.consent[e.participant] = e
            self.consents.setdefault(e.participant, {})[e.form] = e
        elif isinstance(e, j.ConsentFormChanged):
            self.consent_form = e.form
            self.forms_changed.append(e.form)
        elif isinstance(e, j.GameStarted):
            self.games[e.session] = Game(e.session, e.participant, e.phase, e.game, e.recording, e.bias,
                                         scripted=e.scripted)
        elif isinstance(e, j.GameEnded) and e.session in self.games:
            # its reason escaped as every free text read from a journal (`refuse_control`: an older pairplay took
            # a NUL, an ESC), so no reader writes one raw (sessions.csv, the report, status)
            self.games[e.session].ended = msgspec.structs.replace(e, reason=escaped(e.reason))
            self.games[e.session].paused = False
        elif isinstance(e, j.PolicyBuilt) and e.session in self.games and self.games[e.session].ended is not None:
            game = self.games[e.session]
            game.ended = msgspec.structs.replace(game.ended, policy=e.policy)
        elif isinstance(e, (j.GamePaused, j.GameResumed)) and e.session in self.games:
            self.games[e.session].paused = isinstance(e, j.GamePaused)
        elif isinstance(e, j.SessionMarkedInvalid) and e.session in self.games:
            self.games[e.session].invalid = escaped(e.reason)  # (as GameEnded's above)
            self.games[e.session].invalid_ns = e.time_ns
        elif isinstance(e, j.BiasCombined):
            self.combined[e.phase] = e
            self.combinations.append(e)
        elif isinstance(e, j.ParticipantDeleted):
            self.deletions.append(e)
            self.flaws_kept += e.flaws_kept
            # ids are never reused, even after a deletion took the highest one; nor skipped: the deleted one
            # counts once, as the one id it was (a `+= 1` on top of the highest left skipped one when the
            # deleted id was not the highest: p02 of p01..p03 deleted, the next was p05)
            self.ids_given += 1
            self.next_number = max(self.next_number, self.ids_given + 1)


def ids_named_by(e: j.JournalEvent) -> set[str]:
    """The participant ids a journal line names: its `participant`, a copy's `participants`, a combination's
    `human:<id>` users."""
    ids = {getattr(e, "participant", "")} | set(getattr(e, "participants", ()))
    if isinstance(e, j.BiasCombined):
        ids |= {u.removeprefix("human:") for u in e.users if u.startswith("human:")}
    return ids - {"", "deleted"}


@dataclass(frozen=True)
class Step:
    """One step of the guided plan: play a game, or combine a phase's policies."""
    kind: str  # "play" | "combine"
    phase: str
    participant: str = ""
    game: int = 0
    done: bool = False
    blocked: str = ""  # why it cannot run yet ("" = it can)
    scripted: str = ""  # a persona played it (a rehearsal): the label says so
    # what the experimenter should know of it beyond done/blocked (replay/biases.py: a combination whose bias
    # policy was made with a game marked invalid since; a game played on such a policy)
    note: str = ""
    # a person's game that waits for their consent (StudyData.consent_problem): it runs once it is recorded, or
    # played by a persona (a rehearsal needs none); it showed as [open] and was refused when run
    waits: str = ""

    @property
    def label(self) -> str:
        if self.kind == "combine":
            return f"combine the policies of the players before {self.phase} into its bias policy"
        who = f"{self.participant} (scripted: {self.scripted})" if self.scripted else self.participant
        return f"{who}: {self.phase} game {self.game + 1}"


# participants registered by one request (`protocol register --count`, the console's API): a lab
# registers a session's people at once, a few dozen at most; a larger count is a typo that would
# write that many ids into the study's tables and key file
REGISTER_AT_ONCE = 50


class StudyData:
    """A study folder (see the module rule). Thread-safe: the console and the game runner share it."""

    def __init__(self, folder: str | Path, writer: str = "", study_file_edited_ok: bool = False,
                 held: int | None = None):
        """`writer`: the verb that will write the folder ("protocol serve"): it takes the folder's writer lock
        (pairplay/folderlock.py) for this object's life, before the journal is read, and a folder another
        process writes is refused (StudyDataError naming the holder). Without it (a read-only verb) each
        write takes the lock for its own length (`_writing`). `study_file_edited_ok`: a study file changed
        since the study was created is not refused but said in `study_file_changed` (a participant's export
        and deletion: their rights do not wait for the file to be put back). `held`: the folder's writer lock, taken
        already by the verb (replay/copies.py `Copies.hand_over`): this object holds it, in place of taking it."""
        self.folder = Path(folder).resolve()
        self.given = Path(folder)  # as the user gave it: what a refusal names (it named the resolved path)
        if (self.folder / JOURNAL).is_dir():  # it said "not a study folder (no journal.jsonl ...)": there is one
            raise StudyDataError("is a folder where the study's journal is written; a folder is never replaced: "
                                 "remove or rename it", self.given / JOURNAL)
        if said := refusal(self.folder / JOURNAL):  # a pipe: it was "not a study folder"; read, it blocked
            raise StudyDataError(said, self.given / JOURNAL)
        if not (self.folder / JOURNAL).is_file():
            raise not_a_study_folder(self.given)
        self._lock = threading.RLock()
        self._hold: int | None = None
        self._stamp: tuple = ()
        self._started_here: set[str] = set()  # the sessions of games this object journaled as started, not yet ended
        if held is not None:
            self._hold = held
        elif writer:
            if not study_file_edited_ok:  # the user's mistake said before any wait for another writer (`_check_study_file`)
                self._check_study_file(self._created_unlocked())
            self._hold = self._take(writer)
        try:
            self.state = StudyState()
            for e in self.read_journal():
                self.state.evolve(e)
            self._stamp = self._journal_stamp()
            self.study_file_changed = ""
            try:
                self._check_study_file(self.state.created)
            except StudyDataError as changed:
                if not study_file_edited_ok:
                    raise
                self.study_file_changed = str(changed)
            try:
                self.study: Study = load_study(self.given / STUDY_FILE)
            except StudyFileError as err:
                raise StudyDataError(str(err)) from None
            self.settings = _settings(self.given / SETTINGS)  # named as given in a refusal (it named the resolved path)
        except BaseException:
            self.close()
            raise

    # -- one writer per folder (pairplay/folderlock.py) -------------------------
    def _take(self, verb: str) -> int | None:
        return _take_lock(self.folder, self.given, verb)

    def close(self) -> None:
        """Release the folder's writer lock, if this object holds it (the process's end does as well)."""
        with self._lock:
            fd, self._hold = self._hold, None
            folderlock.release(fd)

    def __enter__(self) -> "StudyData":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _journal_stamp(self) -> tuple:
        st = os.stat(self.folder / JOURNAL)
        return (st.st_ino, st.st_size, st.st_mtime_ns)

    @contextlib.contextmanager
    def _writing(self):
        """Every write of the folder goes through here: it holds the writer lock (this object's, or taken for
        the write's length when this object was made read-only) and refuses to write from a stale copy: a
        journal changed since this object read or wrote it (by a process that took no lock: a pairplay
        before the lock, a hand edit) would be overwritten by what this one holds in memory (a deletion
        undone, an id given twice), so the write is refused and the verb is to be started again. Nor does it write
        on a journal that does not fold into consistent tables (`check_folds`: a registration removed by hand), which
        a line more would not mend: the verb's line journaled, its tables failing, a retry's line journaled again."""
        with self._lock:
            taken = None
            if self._hold is None:
                taken = self._hold = self._take(API_WRITE)
            try:
                if self._stamp and self._journal_stamp() != self._stamp:
                    raise StudyDataError(f"{JOURNAL} was changed by another process since this one read it; "
                                         "nothing was written from the stale copy: start this verb again (a running "
                                         "`protocol serve`: stop and start it; was its .pairplay-lock removed?)",
                                         self.given / JOURNAL)
                self.check_folds()  # before anything is written, whatever the verb (a line, a table, a file)
                yield
                self._stamp = self._journal_stamp()
            finally:
                if taken is not None:
                    self.close()

    def fold_problems(self) -> list[str]:
        """What of the journal as it stands does not fold into consistent tables, one item each, naming the lines
        (none: it does): a game, its end, pause or mark of a participant no line registers (their registration
        removed by hand), a game or a registration of a phase the study file does not have. `protocol status`
        lists them; every write refuses while there is one (`check_folds`). Why: a `register` on a folder whose
        p02 registration was removed by hand journaled a new id, then its tables failed ("no participant 'p02'",
        participants.csv left stale), and a retry gave yet another id."""
        phases = {p.id for p in self.study.phase}
        registered = self.state.participants
        if all(g.participant in registered and g.phase in phases for g in self.state.games.values()) and \
                all(r.joins in phases for r in registered.values()):
            return []  # (the usual case: no second read of the journal)
        games = {g.session: g for g in self.state.games.values()}
        unregistered: dict[str, list[int]] = {}
        problems = []
        for n, e in studyjournal.numbered((self.folder / JOURNAL).read_bytes()):
            game = games.get(getattr(e, "session", ""))
            if game is not None and game.participant not in registered:
                unregistered.setdefault(game.participant, []).append(n)
            if isinstance(e, j.GameStarted) and e.phase not in phases:
                problems.append(f"line {n} starts game {e.session} of phase {e.phase!r}, which the study file has not")
            if isinstance(e, j.ParticipantRegistered) and e.participant in registered and e.joins not in phases:
                problems.append(f"line {n} registers {e.participant} for phase {e.joins!r}, which the study file has not")
        for pid, lines in unregistered.items():
            problems.insert(0, f"{pid} has {counted(len(lines), 'game line')} ({_line_numbers(lines)}) and no registration "
                            "line (removed by hand?)")
        return problems

    def check_folds(self) -> None:
        """StudyDataError, one line naming the journal, what does not fold (`fold_problems`) and what to do, if the
        journal as it stands does not fold into consistent tables: before any write (module rule of `_writing`)."""
        problems = self.fold_problems()
        if problems:
            raise StudyDataError(f"does not fold into consistent tables: {'; '.join(problems)}; nothing was written: "
                                 f"put back the line that was removed or changed (a backup of {JOURNAL}), then run "
                                 f"this again (`pairplay protocol status {command_word(self.given)}` lists what does not fold)",
                                 self.given / JOURNAL)

    def _created_unlocked(self) -> j.StudyCreated | None:
        """The journal's first line, read without the writer lock: `protocol init` wrote it whole with the folder and
        nothing rewrites it (appends come after it), so another writer cannot change it under us. None if it does
        not read as a StudyCreated line: the read under the lock says what is wrong, in its words."""
        try:
            with open(self.folder / JOURNAL, "rb") as f:
                first = f.readline()
            return studyjournal.events_of(first, self.given / JOURNAL, self.given)[0] if first.endswith(b"\n") else None
        except (OSError, studyjournal.JournalDamaged):
            return None

    def _check_study_file(self, created: j.StudyCreated | None) -> None:
        """The study file is fixed once the study is created: its bytes against the SHA-256 the journal's
        first line (`created`, StudyCreated) recorded. An edited file is refused, since the folder's games were played
        under the old one (pilot played 2-round games beside 5-round ones, the report left games out). A
        journal without a StudyCreated is refused before this (replay/studyjournal.py: it lost its beginning);
        one with an empty hash was not written by pairplay's `protocol init` (every one records it): there is
        nothing to check against, and it is read as it was. A writer checks it before it takes the folder's lock
        as well (from the first line alone, `_created_unlocked`): an edited file is the user's mistake, said as
        such, where waiting for the lock first said "another pairplay writes this study folder" of a pilot
        that was itself about to refuse the same edit (test_study_guard, under load)."""
        recorded = created.study_file_sha256 if created is not None else ""
        path = self.given / STUDY_FILE
        try:
            text = path.read_bytes()
        except OSError:
            return  # missing or unreadable: load_study says it, in its words
        now = hashlib.sha256(text).hexdigest()
        if recorded and now != recorded:
            raise StudyDataError(f"changed since the study was created (SHA-256 {now[:12]}..., the journal's first "
                                 f"line recorded {recorded[:12]}...: the study file is fixed once created); put back "
                                 "the file the study was created with, or make a new study folder for a new design "
                                 "(`pairplay protocol init NEW_FOLDER --study FILE`)", path)

    # -- creating ------------------------------------------------------------
    @classmethod
    def create(cls, folder: str | Path, study_file: str | Path, key_file: str | Path | None = None) -> "StudyData":
        """A new study folder from a study file; StudyFileError / StudyDataError if it cannot be."""
        given, folder = Path(folder), Path(folder).resolve()
        load_study(study_file)  # refuse a bad file before making anything
        # a folder where the study's files are written, a file where its folders are: named, before anything is
        # made (journal.jsonl a folder was "already a study folder", recordings a file the OS's "File exists")
        check_places(given, owned=tuple(f"{sub}/*{ext}" for sub, ext in SUBFOLDERS.items()),
                     files=[STUDY_FILE, SETTINGS, JOURNAL, folderlock.LOCK_FILE])
        if (folder / JOURNAL).exists():
            # not "already a study folder": a folder named `study` is a word of it, and the line then left out where
            raise StudyDataError(f"already initialised ({JOURNAL} is there); give another folder", given)
        others = other_work(folder)
        if others:  # `protocol init wt1` where the README's walkthrough left recordings/, rebuilt/, merged.json: rc 0,
            # then `session`/`rebuild --out` there were refused (only `protocol` writes a study folder) and the
            # unrelated recordings sat among the study's; a new study starts in a new or empty folder
            shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
            raise StudyDataError(f"holds other work ({shown}); a study folder is made in a new or empty folder "
                                 "(hidden files aside): give another folder", given)
        if key_file is not None:
            key = Path(key_file).resolve()
            if key.is_relative_to(folder):
                raise StudyDataError(f"--key-file {key_file}: must be outside the study folder {given} "
                                     "(names never sit beside the recordings)")
            open_key_file(Path(key_file)).close()  # made now, owner-only: a path that cannot hold it is said here (as
            # given), not at the first registration with a name (an existing key file is kept, only its mode tightened)
            held = key_file_rows(Path(key_file), header=True)  # its header too: a study's before anyone registers
            if held:  # the README's ~/private/keys.csv typed again for a second study: each study then called the
                # other's people crash leftovers and advised removing their lines, another study's only link to them
                whose = f"the key file of study {held[0][2].split(' ', 1)[1]}" if is_key_header(held[0]) and \
                    " " in held[0][2] else f"holds {counted(len(held), 'line')} already (another study's?)"
                raise StudyDataError(f"--key-file {key_file}: {whose}: a key file belongs to one study, whose "
                                     "deletions erase its lines; give a new path (one per study, e.g. "
                                     "~/private/<study>-keys.csv)")
        text = Path(study_file).read_bytes()
        folder.mkdir(parents=True, exist_ok=True)
        for sub in SUBFOLDERS:
            (folder / sub).mkdir(exist_ok=True)
        atomic_write(folder / STUDY_FILE, text)
        atomic_write(folder / folderlock.LOCK_FILE, b"")  # there from the start: a refused verb changes no file
        atomic_write(folder / SETTINGS, msgspec.json.encode(
            {"key_file": str(Path(key_file).resolve()) if key_file else ""}))
        study = load_study(folder / STUDY_FILE)
        created = j.StudyCreated(study=study.study.id, study_file_sha256=hashlib.sha256(text).hexdigest(),
                                 software_version=__version__, time_ns=time.time_ns())
        if key_file is not None:  # the key file names its study before anyone registers: no other init takes it
            with open_key_file(Path(key_file)) as f:
                csvcell.writer(f).writerow(key_header(f"{created.study}@{created.time_ns}"))
        try:
            atomic_write(folder / JOURNAL, j.encode_line(created))
        except BaseException:  # no study was made: its header goes (a retry of this init takes the file again)
            if key_file is not None:
                os.truncate(key_file, 0)  # (it was empty: `held` above refused any other)
            raise
        made = cls(given)
        made.write_folder_manifest()
        return made

    # -- the journal ---------------------------------------------------------
    def read_journal(self) -> list[j.JournalEvent]:
        """Every event of the journal; StudyDataError naming a line that does not read and what to do (a
        torn last line: `protocol repair`; replay/studyjournal.py)."""
        try:
            return studyjournal.events_of((self.folder / JOURNAL).read_bytes(), self.given / JOURNAL, self.given)
        except studyjournal.JournalDamaged as err:
            raise StudyDataError(str(err)) from None

    def append(self, event: j.JournalEvent) -> j.JournalEvent:
        with self._writing():
            if not event.time_ns:
                event = msgspec.structs.replace(event, time_ns=time.time_ns())
            with open(self.folder / JOURNAL, "a+b") as f:  # (+: its last byte is read)
                # a last line whole but for its end of line (a crash cut just that) would run on into this one
                ends_open = f.tell() > 0 and os.pread(f.fileno(), 1, f.tell() - 1) != b"\n"
                f.write((b"\n" if ends_open else b"") + j.encode_line(event))
                f.flush()
                os.fsync(f.fileno())
            self.state.evolve(event)
            if isinstance(event, j.GameStarted):  # a game this process runs (delete_participant's "running")
                self._started_here.add(event.session)
            elif isinstance(event, j.GameEnded):
                self._started_here.discard(event.session)
            self.write_folder_manifest()
            return event

    def append_naming(self, event: j.JournalEvent, written: str) -> j.JournalEvent:
        """`append` the line that names `written`, a file of the folder (relative path; "" for none) just put in
        place: the file is removed if the line is not written (`journaled_or_removed`)."""
        if not written:
            return self.append(event)
        with journaled_or_removed(self.folder / written) as line:
            testpause.pause("policy-written")
            with line():
                return self.append(event)

    def write_folder_manifest(self) -> None:
        """The study folder's manifest (PROTOCOL_MANIFEST, pairplay/outputs.py's format): its files as the journal
        says them (the study file, settings, journal, tables, each game's recording, its recorder's journal and
        its policy, each bias policy, each participant's export), so that no other verb's folder output takes one
        (outputs.check_theirs). Written again at each journal line: a deletion's leaves their games out."""
        files = {STUDY_FILE, SETTINGS, JOURNAL, *TABLES}
        for g in self.state.games.values():
            files |= {g.recording, f"{g.recording}.journal"}
            if g.ended is not None and g.ended.policy:
                files.add(g.ended.policy)
        files |= {c.output for c in self.state.combinations}  # an earlier bias policy too: kept for the record
        files |= {f"exports/{pid}.zip" for pid in self.state.participants}
        write_manifest(self.folder / PROTOCOL_MANIFEST, sorted(files))

    # -- participants --------------------------------------------------------
    @property
    def key_file(self) -> Path | None:
        return Path(self.settings["key_file"]) if self.settings.get("key_file") else None

    def register(self, joins: str, label: str = "", consent: bool = False) -> str:
        """Register a participant for phase `joins`; returns the new pseudonymous id.

        `label` (a name, an e-mail...) goes only to the key file; refused without one, and with a control
        character (`register_many`, the one way in). `consent`: the person signed the study's consent form now
        (`record_consent`); without it the id plays only as a persona (a rehearsal) until it is recorded."""
        with self._writing():
            try:
                self.study.phase_by_id(joins)
            except KeyError as err:
                raise StudyDataError(err.args[0]) from None
            if label and self.key_file is None:
                raise StudyDataError("this study has no key file: register by pseudonymous id only "
                                     "(or create the study with `pairplay protocol init FOLDER --key-file PATH`, "
                                     "the key file outside its folder)")
            # one past every id a record shows given, not the journal's alone: a crash between the key-file line
            # and the journal line, or a torn registration set aside by repair, gave the same id twice
            # (and counted: a deletion keeps no id, so the ids given are the journal's count plus these, which are
            # not in it; else p03 left by a crash, p04 registered and deleted, gave p04 again)
            on_record = self.ids_on_record()
            unjournaled = on_record - set(self.state.participants)
            numbers = [int(i[1:]) + 1 for i in on_record if i[1:].isdigit()]
            pid = f"p{max([self.state.next_number, self.state.ids_given + len(unjournaled) + 1] + numbers):02d}"
            if label:
                with open_key_file(self.key_file) as f:  # never a formula (pairplay/csvcell.py)
                    csvcell.writer(f).writerow([pid, label, self.key_owner])
            self.append(j.ParticipantRegistered(participant=pid, joins=joins))
            if consent:
                self.record_consent(pid)
            return pid

    # -- informed consent ----------------------------------------------------
    @property
    def consent_form(self) -> str:
        """The consent form a person's game needs consent to: the last `protocol consent-form` (an ethics
        amendment, journaled ConsentFormChanged), else the study file's `consent_form` (fixed with the folder)."""
        return self.state.consent_form if self.state.consent_form is not None else self.study.study.consent_form

    @property
    def forms_had(self) -> list[str]:
        """Every consent form the study has had, in order: the study file's, then each `protocol consent-form`'s."""
        return list(dict.fromkeys([self.study.study.consent_form, *self.state.forms_changed]))

    def record_consent(self, pid: str, form: str | None = None, given_ns: int | None = None) -> j.ConsentGiven:
        """Journal that registered participant `pid` gave their informed consent to `form` (default: the study's
        `consent_form` now), now (None) or at `given_ns` (a consent held on paper, recorded later: both times kept).
        A journaled consent cannot be taken back, so what can only be a typo is refused: a form the study never
        had (`forms_had`), a time in the future or more than a year before the study folder was made (2016 for
        2026; 1970-01-01 was the journal's "given when recorded", 0, and became now; CONSENT_BEFORE_STUDY_NS:
        forms signed at recruitment, before the folder was made, are a study's everyday case). Refused if it is recorded already to that
        form: a new version of the form (`change_consent_form`, an ethics amendment) is recorded again."""
        with self._writing():
            self.participant(pid)
            form = self.consent_form if form is None else form
            if not consent_form_ok(form):
                raise StudyDataError(f"consent form {form[:40]!r} {CONSENT_FORM_RULE}")
            if form not in self.forms_had:
                raise StudyDataError(f"{pid}: consent form {form[:40]!r} is not one this study has had ("
                                     + ", ".join(repr(f) if f else "the unnamed form" for f in self.forms_had)
                                     + "): give the version they signed")
            now = time.time_ns()
            if given_ns is not None and given_ns > now:  # a typo of the year, a clock: never journaled ahead
                raise StudyDataError(f"{pid}: consent given at {_utc(given_ns)} is in the future (now "
                                     f"{_utc(now)}): give the time they signed")
            made = self.state.created.time_ns if self.state.created is not None else 0
            if given_ns is not None and given_ns < made - CONSENT_BEFORE_STUDY_NS:
                raise StudyDataError(f"{pid}: consent given at {_utc(given_ns) or '1970-01-01T00:00:00Z'} is more "
                                     f"than a year before the study folder was made ({_utc(made)}): give the time "
                                     f"they signed, from a year before then up to now")
            had = self.state.consents.get(pid, {}).get(form)
            if had is not None:
                raise StudyDataError(f"{pid}: consent to {consent_words(had)} is recorded already")
            return self.append(j.ConsentGiven(participant=pid, form=form, given_ns=given_ns or 0))

    def change_consent_form(self, form: str) -> tuple[j.ConsentFormChanged, list[str]]:
        """Journal `form` as the study's consent form from now on (an ethics amendment: the study file stays as
        it was made); returns its line and the participants whose consent is to an earlier form only: their
        next game waits for their consent to this one. Refused if it is the form already, or names none (""
        is the study file's "not named", never an amendment)."""
        with self._writing():
            if not form:
                raise StudyDataError("consent form '': an amendment names the new form's version (\"v2 2026-11\")")
            if not consent_form_ok(form):
                raise StudyDataError(f"consent form {form[:40]!r} {CONSENT_FORM_RULE}")
            if form == self.consent_form:
                raise StudyDataError(f"the study's consent form is {form!r} already")
            line = self.append(j.ConsentFormChanged(form=form))
            return line, [pid for pid in self.state.participants if pid in self.state.consent
                          and form not in self.state.consents.get(pid, {})]

    def consent_problem(self, pid: str) -> str:
        """Why `pid`'s consent does not let a person play: "" if it is recorded to the study's form of now;
        none recorded; or only to an earlier form (the study's form changed since: `change_consent_form`)."""
        form = self.consent_form
        held = self.state.consents.get(pid, {})
        if form in held:
            return ""
        if not held:
            return "no consent recorded"
        return (f"consent to {', '.join(repr(f) if f else 'the unnamed form' for f in held)} only, the study's consent "
                f"form is now {form!r}")

    def check_consent(self, pid: str) -> None:
        """StudyDataError unless a person's consent is recorded for `pid` to the study's consent form of now: the
        rule before any game a person plays (services/protocol.py). A persona needs none (no person, no
        personal data: `protocol pilot`, `serve --pilot`). A study folder made before consent was recorded (no
        ConsentGiven in its journal) is read as it is; its people's next games wait for `protocol consent`;
        so do those whose consent is to an earlier form once the form changes."""
        problem = self.consent_problem(pid)
        if problem:
            raise StudyDataError(f"{pid} has {problem}: a person plays only once their informed consent is "
                                 f"recorded (`pairplay protocol consent {command_word(self.given)} {command_word(pid)}`, "
                                 "or the console's Record consent, once they have signed the consent form"
                                 + (f" {self.consent_form!r}" if self.consent_form else "")
                                 + "); a persona (pilot) needs none")

    @property
    def key_owner(self) -> str:
        """This study in its key file's lines (their third cell): its id and the time it was created, so two
        folders made from one study file differ. A key file belongs to one study (`create` refuses one holding
        lines); this keeps two that share one anyway (an empty one taken twice, an older pairplay) apart."""
        created = self.state.created
        return f"{created.study}@{created.time_ns}" if created is not None else ""

    def _own_key_line(self, row: list[str]) -> bool:
        # a line of two cells (an older pairplay's) does not say its study: it stays this study's, as it was
        return len(row) < 3 or csvcell.value(row[2]) == self.key_owner

    def key_file_ids(self) -> list[str]:
        """The ids of this study's lines of the key file, in its order (one id twice: given twice by pairplay <=
        this fix); another study's lines are not read. StudyDataError if the study has one that cannot be read
        (an unmounted drive): its ids are not known."""
        key = self.key_file
        if key is None:
            return []
        return [r[0] for r in key_file_rows(key) if self._own_key_line(r)]

    def ids_on_record(self) -> set[str]:
        """Every id a record shows was given, beyond the journal's registrations (`records_of_ids`). None is
        given again."""
        return set(self.records_of_ids())

    def records_of_ids(self, key_file: bool = True) -> dict[str, list[str]]:
        """{id: the records that show it given, by their names}: the key file's lines (written before
        the journal line: a crash between them leaves the key line alone), participants.csv (the tables as last
        written), the registrations of torn lines `protocol repair` set aside, the journal's lines (a game, an
        export... whose registration a hand edit removed), and the names of exports/, recordings/ and policies/
        (a session's name holds its participant's id: `session_id`). A hand edit that removed an id from some
        records leaves it in the others: it is never given again, and `unregistered_ids` says where it is.
        `key_file` False: the key file left out (`protocol status` beside an unreachable one)."""
        found: dict[str, list[str]] = {}

        def add(ids, place: str) -> None:
            for pid in ids:
                found.setdefault(pid, [])
                if place not in found[pid]:
                    found[pid].append(place)

        add(self.key_file_ids() if key_file else [], KEY_RECORD)
        if said := refusal(self.folder / "participants.csv"):  # before opening: a pipe blocked (pairplay/inputs.py)
            raise StudyDataError(said, self.given / "participants.csv")
        try:
            with open(self.folder / "participants.csv", encoding="utf-8", newline="") as f:
                add([r[0] for r in list(csv.reader(f))[1:] if r], "participants.csv")
        except FileNotFoundError:
            pass
        except (OSError, UnicodeDecodeError, csv.Error) as err:
            raise StudyDataError(f"cannot read it: {getattr(err, 'strerror', None) or err}",
                                 self.given / "participants.csv") from None
        add(studyjournal.torn_ids(self.folder / JOURNAL), TORN_RECORD)
        add(self.state.named - set(self.state.participants), "other journal lines")
        session = re.compile(rf"(?<![A-Za-z0-9]){re.escape(self.study.study.id)}-(p[0-9]+)-")
        for sub, pattern in (("exports", re.compile(r"(p[0-9]+)\.zip")), ("recordings", session), ("policies", session)):
            try:
                names = [f.name for f in (self.folder / sub).iterdir()]
            except FileNotFoundError:
                continue
            except OSError as err:
                raise StudyDataError(f"cannot list it: {err.strerror or err}", self.given / sub) from None
            add(sorted(m[1] for m in map(pattern.fullmatch if sub == "exports" else pattern.search, names) if m), f"{sub}/")
        return found

    def unregistered_ids(self, key_file: bool = True) -> dict[str, str]:
        """{id: what it is} for each id a record shows given (`records_of_ids`) that the journal does not register:
        a crash between the key-file line and the journal line, a torn line set aside, a hand edit. None has data
        the study can use; none is given again. Said by `protocol status` and listed by the console."""
        notes = {}
        for pid, places in self.records_of_ids(key_file).items():
            if pid in self.state.participants:
                continue
            if KEY_RECORD in places and set(places) <= {KEY_RECORD, TORN_RECORD}:
                notes[pid] = ("in the key file only: not registered (a crash cut its registration, or a hand edit): "
                              "no data here; the id is not given again")
            else:
                notes[pid] = f"not registered in the journal, but named in {', '.join(places)}: the id is not given again"
        return dict(sorted(notes.items(), key=lambda kv: (len(kv[0]), kv[0])))

    def id_notes(self) -> tuple[dict[str, str], str]:
        """(`unregistered_ids`, "" or why the key file's ids are left out of it): what `protocol status` and the
        console say of the ids the journal does not register. A key file not there or unreadable (an unmounted
        drive) is said, not raised: these only read, beside it (a registration refuses: `key_file_ids`)."""
        try:
            return self.unregistered_ids(), ""
        except StudyDataError as err:
            if self.key_file is None:
                raise
            try:
                self.key_file_ids()
            except StudyDataError as key:
                return self.unregistered_ids(key_file=False), f"the ids of the key file are not checked here: {one_line(key)}"
            raise err from None

    def register_many(self, joins: str, count: int = 1, label: str = "", *, count_name: str = "--count",
                      label_name: str = "--name", consent: bool = False) -> list[str]:
        """Register `count` participants for phase `joins` (the rule of the CLI and the console alike): a
        label names one person, so it goes with a count of 1 only. `count_name` / `label_name` are the
        caller's words for them (the CLI's options, the console's JSON keys). Raises StudyDataError."""
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= REGISTER_AT_ONCE:
            raise StudyDataError(f"{count_name} must be a whole number 1..{REGISTER_AT_ONCE}, got {count!r}")
        if label and count != 1:
            raise StudyDataError(f"{label_name} registers one participant: leave out {count_name}")
        # a newline became a space in the key file without a word (a new user's trial)
        refuse_control(label, label_name, "the name")
        return [self.register(joins, label, consent) for _ in range(count)]

    def mark_invalid(self, session: str, reason: str) -> j.SessionMarkedInvalid:
        """Journal a game as invalid (left out of every report, its step asked again); the reason is required and
        kept as given, stripped. A bias policy combined from the game is combined again, into a new file, once the
        step is played again (replay/biases.py). Raises StudyDataError for an unknown session, an empty reason, or
        a game marked already (its first reason stays: a second mark replaced it everywhere), or a reason that is
        not one line of at most MAX_REASON characters (`refuse_control`)."""
        if not reason.strip():  # the report says why a game is left out: a blank is no answer
            raise StudyDataError("marking a session invalid needs a reason")
        # a NUL or an ESC went raw into sessions.csv and report.md (trial33 I); bounded as a pause's reason is
        refuse_control(reason, "the reason", "it", MAX_REASON)
        game = self.state.games.get(session)
        if game is None:
            raise StudyDataError(f"no session {session!r} in this study")
        if game.invalid:  # a second mark replaced the first reason in every reader (a new user's trial)
            raise StudyDataError(f"{session} is marked invalid already ({game.invalid}, "
                                 f"{_utc(game.invalid_ns) or 'time not journaled'}); nothing written")
        if game.ended is None:  # the console's page disables its button for it; its API marked one mid-game
            # (trial27 F10): a mark before the game's end, the step then offered again beside the game still playing
            raise StudyDataError(f"{session}: the game is running: abort it or wait for its end" if self.running(game)
                                 else f"{session}: {self.unended_note(game) or 'its end is not journaled'}; mark it "
                                 "once its end is journaled")
        event = self.append(j.SessionMarkedInvalid(session=session, participant=game.participant,
                                                   reason=reason.strip()))
        self.write_tables()
        return event

    def marked_line(self, marked: j.SessionMarkedInvalid) -> str:
        """The one line that says a mark (`protocol mark-invalid`, the console's answer): the game, the reason, and
        what it did to a bias policy combined from the game (replay/biases.py `marked_note`: it said only
        "marked invalid", and the plan kept the bias policy made with it, a new user's trial)."""
        note = biases.marked_note(self.state, marked.session)
        return f"{marked.session} marked invalid: {marked.reason}" + (f"; {note}" if note else "")

    def running(self, g: Game) -> bool:
        """Whether game `g` is being played now: journaled as started and not ended, and either run by this
        object (the folder's one writer: pairplay/folderlock.py) or its recording still held by a live recorder
        (pairplay/livelock.py). The rule by which a running game is not marked, exported or deleted."""
        return g.ended is None and (g.session in self._started_here or is_live(self.folder / g.recording))

    def participant(self, pid: str) -> j.ParticipantRegistered:
        p = self.state.participants.get(pid)
        if p is None and self.key_file is not None and self.key_file.is_file() and pid in self.key_file_ids():
            # a line of this study's (its third cell says so); one of an older pairplay's two cells may be another
            # study's sharing the file (trial27 F8): that one is said, not advised away
            told = all(len(r) >= 3 for r in key_file_rows(self.key_file) if r[0] == pid and self._own_key_line(r))
            raise StudyDataError(f"{pid} is in the key file but was never journaled (a crash cut its registration): "
                                 "nothing of theirs is in the study; the id is not given again; to erase their "
                                 f"name, remove its line from the key file {self.key_file} by hand"
                                 + ("" if told else " (if it is this study's: a line of two cells, written by an "
                                    "older pairplay, does not say its study, and another study may share the file)"))
        if p is None:
            raise StudyDataError(f"no participant {pid!r} in study {self.study.study.id!r} "
                                 f"(registered: {', '.join(self.state.participants) or 'none'})")
        return p

    def returning(self, pid: str, phase: str) -> bool:
        """Did `pid` play a phase before `phase`?"""
        ids = [p.id for p in self.study.phase]
        return ids.index(self.participant(pid).joins) < ids.index(phase)

    def players(self, phase_id: str) -> list[str]:
        """Who plays `phase_id`, in registration order (thesis 7.2: phase 2 takes everyone)."""
        ids = [p.id for p in self.study.phase]
        phase = self.study.phase_by_id(phase_id)
        upto = ids.index(phase_id)
        return [pid for pid, r in self.state.participants.items()
                if r.joins == phase_id or (phase.players == "all" and r.joins in ids and ids.index(r.joins) < upto)]
        # (a registration of a phase the study has not, a hand edit: no phase's player; `fold_problems` says it)

    # -- the plan ------------------------------------------------------------
    def games_of(self, pid: str, phase: str | None = None) -> list[Game]:
        return [g for g in self.state.games.values() if g.participant == pid and (phase is None or g.phase == phase)]

    def scripted_as(self, pid: str) -> str:
        """The personas that played `pid`'s games instead of a person (a rehearsal), "+"-joined; "" if none."""
        return "+".join(dict.fromkeys(g.scripted for g in self.games_of(pid) if g.scripted))

    def user_names(self, combined: j.BiasCombined) -> dict[str, str]:
        """How to name each user of a combination (its `users`, `profiles` and `decided_by` say `human:<id>`,
        the sessions' participant): `sim:<persona> as <id>` if personas played all its combined games,
        `human:<id> (with scripted games: <persona>)` if some; a person's id stays as it is."""
        by_policy = {g.ended.policy: g for g in self.state.games.values() if g.ended is not None and g.ended.policy}
        names = {}
        for user in dict.fromkeys([*combined.users, *combined.profiles]):
            pid = user.split(":", 1)[1] if user.startswith("human:") else user
            games = [by_policy[p] for p in combined.inputs if p in by_policy and by_policy[p].participant == pid]
            personas = "+".join(dict.fromkeys(g.scripted for g in games if g.scripted))
            if personas:
                names[user] = (f"sim:{personas} as {pid}" if all(g.scripted for g in games)
                               else f"{user} (with scripted games: {personas})")
        return names

    def combined_games(self, phase: str, include_scripted: bool = False) -> list[Game]:
        """The games a bias policy of `phase`'s games combines: its valid ones that people played, unless
        `include_scripted` (a rehearsal asked for: `protocol pilot`, `serve --pilot`); all of them when no
        person played one (a rehearsal's folder), so a rehearsal reaches the next phase."""
        valid = [g for g in self.state.games.values() if g.phase == phase and g.valid_complete]
        people = [g for g in valid if not g.scripted]
        return valid if include_scripted else people or valid

    def plan(self) -> list[Step]:
        """Every step of the protocol, in order, with what is done and what is blocked."""
        steps: list[Step] = []
        for phase in self.study.phase:
            blocked = ""
            if phase.bias:
                earlier = [s for s in steps if s.phase == phase.bias and s.kind == "play"]
                players = {s.participant for s in earlier}
                waiting = not earlier or not all(s.done for s in earlier)
                # a bias policy made with a game marked invalid since is combined again (replay/biases.py)
                flaw = biases.flawed(self.state, phase.id)
                done = phase.id in self.state.combined and flaw is None
                # nobody registered is not "games not all played": that said to play games nobody could
                # (an empty study, a new user's trial); what to do first is to register people
                why = (f"nobody plays {phase.bias} yet: register its participants first (at least 2)" if not earlier
                       else f"it needs at least 2 players: register another participant for {phase.bias}"
                       if len(players) < 2 else ("the games of " + phase.bias + " are not all played") if waiting
                       else "")
                steps.append(Step("combine", phase.id, done=done, blocked="" if done else why,
                                  note=biases.step_note(self.state, phase.id)))
                if flaw is not None:  # no game starts on it
                    blocked = (f"the bias policy of {phase.id} ({flaw.output}) was {biases.flaw_words(self.state, flaw)}: "
                               "combine it again first")
                elif not done:
                    blocked = f"the bias policy of {phase.id} is not combined yet"
            for pid in self.players(phase.id):
                done_games = {g.game: g for g in self.games_of(pid, phase.id) if g.valid_complete}
                for game in range(phase.games):
                    g = done_games.get(game)
                    steps.append(Step("play", phase.id, pid, game, done=g is not None, blocked=blocked,
                                      scripted=g.scripted if g else "",
                                      note=biases.game_note(self.state, g) if g else "",
                                      waits="" if g else self.consent_problem(pid)))
        return steps

    def next_step(self) -> Step | None:
        """The plan's first step not done; None when it is complete, and when nobody is registered: a study's
        first step is then to register people, which is no step of the plan (its blocked combination was the
        console's "next" while `protocol status` said to register first: trial27 F12a)."""
        if not self.state.participants:
            return None
        for s in self.plan():
            if not s.done:
                return s
        return None

    def session_id(self, pid: str, phase: str, game: int) -> str:
        """A fresh session id: <study>-<pid>-<phase>-g<game>[-r<n> for a retry]."""
        base = f"{self.study.study.id}-{pid}-{phase}-g{game + 1}"
        tries = sum(1 for g in self.state.games.values() if g.session.startswith(base))
        return base if tries == 0 else f"{base}-r{tries}"

    def game_index(self, pid: str, phase: str, game: int) -> int:
        """The game's index across the participant's games (it names the deal stream)."""
        index = 0
        for p in self.study.phase:
            if p.id == phase:
                return index + game
            index += p.games if pid in self.players(p.id) else 0
        raise StudyDataError(f"no phase {phase!r}")

    # -- a game's recording --------------------------------------------------
    def game_recording(self, g: Game) -> tuple[Path, str]:
        """(the file that stands for game `g`'s recording, "" or the words naming it): the one its GameStarted
        names, or, when that one was not finished (its recorder's journal beside it) or is gone (`recover`'s line
        says to remove the cut file and its journal once its output is kept), the copy `pairplay recover` wrote
        beside it (`<stem>.recovered.mcap`, replay/recover.py `default_output`: written whole or not at all,
        pairplay/outputs.py), named "its recovered copy recordings/<stem>.recovered.mcap". Every reader of a
        game's recording goes through it: the study kept naming the cut file, and said "not finished ... recover
        completes it" after the user had done exactly that (a new user's trial). The copy is judged as any game's
        file is (`recording_of`, `not_this_game`): one of another session, or cut still, is not the game."""
        path = self.folder / g.recording
        copy = default_output(path)
        if (wal_path(path).exists() or not path.exists()) and copy.is_file() and not is_live(path):
            return copy, f"its recovered copy {copy.relative_to(self.folder).as_posix()}"
        return path, ""

    def recording_of(self, g: Game, make: Callable[[], Callable[[list], Any]] = lambda: _ignored):
        """(its read recording (reader.EventLog), `make()`'s fold of its events, "") if game `g`'s recording can stand
        for the game, else (None, None, why not, in the words the report names the game by): missing; holding no
        session (a 0-byte file, the ~1 KB an interrupted `session --force` leaves: reader.EventLog.no_session, the
        reader's words); damaged (events lost: EventLog.lost, a recovered file's source's losses among them); holding no
        whole round (check.no_whole_round); not this game's (`not_this_game`: a `session --force --session <its id>
        --out STUDY/recordings` replaced it with another session); or without the game's SessionEnded (a cut file:
        its rounds are a part of the game). A
        journal that says "completed" does not make a file that holds none of it the game: its picks would
        silently be no picks.
        The fold is given the events (lists of reader.RecordedEvent) as they are read, a chunk's at a time, none kept
        (reader.fold_log: a report of many long sessions held each file's records and events whole; the EventLog's
        `events` is empty but for a file read whole); the fold of a file refused is dropped."""
        from .check import check_recording, no_whole_round

        path, _ = self.game_recording(g)
        if said := refusal(path):  # a pipe there was "recording missing" (pairplay/inputs.py)
            return None, None, f"recording {path.name} {said}"
        if not path.is_file():
            return None, None, "recording missing"
        try:
            check_recording(path)
            log, (watch, fold) = fold_log(path, None, lambda: _Watched(make()))
        except InputError as err:  # not MCAP at all, or a file of nothing: no session either
            return None, None, f"recording holds no session: {err.what}"
        except OSError as err:
            return None, None, f"recording unreadable: {err.strerror or err}"
        if watch.first is None:  # no SessionStarted (the file was read whole: its EventLog says why, reader.fold_log)
            return None, None, f"recording {log.no_session}"
        if log.lost:  # (a new user's trial: messages that do not decode were left out of its picks, no word)
            return None, None, f"recording damaged: {log.lost}"
        why = no_whole_round(watch.said, log.truncated, log.damaged)
        if why:
            return None, None, f"recording {why}{journal_more(path)}"
        why = self.not_this_game(g, watch.first.config)
        if why:
            return None, None, f"recording is not this game's: {why}"
        if not any(type(e).__name__ == "SessionEnded" for e in watch.said):  # (the game's: RoundWatch)
            # its rounds are a part of the game, not the game (a new user's trial: a cut recording was one of
            # "5 valid games", its partial rounds in the figures)
            # (a recovered copy of a cut file: its source's cut, in the reader's words: reader.EventLog.source_cut)
            cut = f"truncated: {log.brief}; " if log.truncated else f"{log.source_cut}; " if log.source_cut else ""
            return None, None, f"recording {cut}no SessionEnded: its rounds are a part of the game{journal_more(path)}"
        return log, fold, ""

    def not_this_game(self, g: Game, config) -> str:
        """Why a session's config (its SessionStarted's) is not game `g`'s as the journal and plan say, in
        words ("" if it is): its session id, participant (`human:<id>`), the phase's rounds, and the persona of a
        scripted game (one a person played is taken as the journal says: its config's `scripted` is not read)."""
        rounds = self.study.phase_by_id(g.phase).rounds
        said = [f"session {config.session}" if config.session != g.session else "",
                f"participant {config.participant}" if config.participant != f"human:{g.participant}" else "",
                counted(config.rounds, "round") if config.rounds != rounds else "",
                f"persona {config.scripted or config.persona or 'none'}" if g.scripted and config.scripted != g.scripted else ""]
        said = [s for s in said if s]
        if not said:
            return ""
        plays = f"human:{g.participant}" + (f" (scripted: {g.scripted})" if g.scripted else "")
        return (f"it holds {', '.join(said)}; the journal's game is {g.session} of {plays}, "
                f"{counted(rounds, 'round')}")

    def _not_this_games_file(self, g: Game, path: Path) -> str:
        """`not_this_game` of the session the recording at `path` starts ("" if it starts none or cannot be read:
        what reads it next says so)."""
        try:
            _, started = events_of(path, only=frozenset({"SessionStarted"}), tags=frozenset({"SessionStarted"}))
        except (InputError, OSError):
            return ""
        return self.not_this_game(g, started[0].config) if started else ""

    # -- what a signal left unsaid -------------------------------------------
    def build_missing_policies(self) -> list[str]:
        """Say in the journal what a stopped server could not, from the recordings (the event log is the
        truth): the policy of every completed game journaled without one (a signal during its
        questionnaire: PolicyBuilt), and the end of every game whose recording is finished and ended
        but whose end was never journaled (a process gone while it read the recording back:
        GameEnded, as `game_end`), and the end of every game stopped before its recording began (a second signal
        as `protocol serve` stopped it: `_never_recorded`; journaled aborted, so its step is played again). One
        line for each game said: done, or why its policy is not (a
        recording missing, unfinished, unreadable or partial: the game is left as it is, and the
        combination refuses to go without it, StudyRunner.combine). A completed game whose journaled
        policy file is gone (deleted by hand) is built again the same way and journaled (PolicyBuilt): it
        was neither rebuilt nor said, since the journal named a policy."""
        lines, changed = [], 0
        with self._writing():
            for g in list(self.state.games.values()):
                path, copy = self.game_recording(g)  # (the copy `pairplay recover` made of a cut one, named)
                source = copy or "its recording"
                if g.ended is None:
                    if path.is_file() and not wal_path(path).exists() and _finished_game(path) \
                            and not self._not_this_games_file(g, path):  # another session's end is not its
                        ended = game_end(self.folder, g.session, g.participant, path, force=True)
                        ended = self.append_naming(ended, ended.policy)
                        lines.append(f"{g.session}: journaled {ended.outcome} from {source} (the server "
                                     "stopped before it said how the game ended)")
                        lines += self._counted_once(g)
                        changed += 1
                    elif (cut := self._cut(g, path)) is not None:
                        # a second signal as the recorder finished, a crash: it was left "running", said by nothing,
                        # and its step played again as if never played (a new user's trial)
                        self.append(j.GameEnded(session=g.session, participant=g.participant, outcome=cut.outcome,
                                                reason=cut.reason, rounds_played=cut.rounds, policy="",
                                                questionnaire=cut.answered))
                        lines.append(f"{g.session}: journaled {cut.outcome}{self._cut_words(g, copy, cut)}")
                        lines += self._counted_once(g)
                        changed += 1
                    elif self._never_recorded(g):
                        self.append(j.GameEnded(session=g.session, participant=g.participant, outcome="aborted",
                                                reason=NEVER_RECORDED, rounds_played=0, policy="", questionnaire=False))
                        lines.append(f"{g.session}: journaled aborted ({NEVER_RECORDED}); its step is played again")
                        changed += 1
                    elif g.session not in self._started_here and (note := self.unended_note(g)):
                        lines.append(note)  # another session's file: said at each start, left as it is
                    continue  # otherwise running (here, or a recorder writes it): as it was
                gone = bool(g.ended.policy) and not (self.folder / g.ended.policy).is_file()
                if g.ended.outcome != "completed" or (g.ended.policy and not gone):
                    continue
                was = f"its policy {g.ended.policy} is missing; " if gone else ""
                why = ""
                named = copy or f"its recording {g.recording}"
                if not path.is_file():
                    why = f"its recording {g.recording} is missing"
                elif wal_path(path).exists():
                    why = (f"its recording {g.recording} was not finished (its recorder's journal is beside it: "
                           f"`pairplay recover {command_word(path)}` writes its recovered copy beside it, which the next serve, "
                           "pilot or report builds it from)")
                else:
                    try:
                        rebuilt = rebuild_recording(path)
                    except (InputError, OSError) as err:
                        why = f"{named} cannot be read: {one_line(err)}"
                    else:
                        if rebuilt.partial:
                            why = f"{named} is partial: {rebuilt.partial}"
                        elif self.not_this_game(g, rebuilt.config):  # (a `session --force` over it)
                            why = f"{named} is not this game's: {self.not_this_game(g, rebuilt.config)}"
                    if not why:
                        try:  # force: ours, of this recording (the file a build cut before its journal line wrote)
                            policy = write_game_policy(self.folder, rebuilt, force=True)
                        except (OutputError, OSError) as err:
                            why = f"its policy cannot be written: {one_line(err)}"
                if why:
                    lines.append(f"{g.session}: completed, but {was}no policy built: {why}")
                    continue
                self.append_naming(j.PolicyBuilt(session=g.session, participant=g.participant, policy=policy), policy)
                lines.append(f"{g.session}: {was}policy built from {source}: {policy}")
                changed += 1
            if changed:
                self.write_tables()
        return lines

    def _cut(self, g: Game, path: Path) -> CutEnd | None:
        """What the cut recording of game `g` (journaled as started, never as ended) says of its end
        (replay/cutgame.py), or None when it is not a cut recording of a game left by a process gone: started by
        this object (it runs here), written by a live recorder, nothing recorded (`_never_recorded`), or a file of
        another session (`not_this_game`: left as it is). `path`: the file standing for its recording
        (`game_recording`). No other process runs a game of the folder while this one writes it
        (pairplay/folderlock.py)."""
        original = self.folder / g.recording
        if g.session in self._started_here or is_live(original):
            return None
        if not path.exists() and not wal_path(original).exists():
            return None
        if path.is_file() and self._not_this_games_file(g, path):
            return None
        return cut_end(path, original, g.session)

    def _cut_words(self, g: Game, copy: str, cut: CutEnd) -> str:
        """The rest of a cut game's line after its outcome (`build_missing_policies`, `protocol status` in the
        future tense): where its end was found and what becomes of its policy, or that its step is played again."""
        original = self.folder / g.recording
        source = copy or f"its cut recording {g.recording}"
        if cut.ended is None:
            return (f" ({CUT_BEFORE_END}: {source}, after {counted(cut.rounds, 'whole round')}); its step is "
                    "played again")
        said = f" from {source}: it was cut after the game's end (its SessionEnded is in {cut.where})"
        if cut.outcome != "completed":  # (interrupted, aborted by the experimenter: its SessionEnded says)
            return f"{said}; its step is played again"
        if not copy:
            said += (f"; its policy: `pairplay recover {command_word(original)}` writes its recovered copy, which the next serve, "
                     "pilot or report builds it from")
        return said

    def _counted_once(self, g: Game) -> list[str]:
        """Game `g` just journaled completed counts once with its step (the study's rule, docs/study.md): when its
        step was played again before its end was journaled (its replay completed first: counted, combined,
        reported), `g` is marked invalid, and said; [] otherwise. Both had counted as valid games (a new user's
        trial: 13 valid games of a 12-game plan)."""
        if not self.state.games[g.session].valid_complete:
            return []
        first = next((o for o in self.state.games.values() if o.session != g.session and o.valid_complete
                      and (o.participant, o.phase, o.game) == (g.participant, g.phase, g.game)), None)
        if first is None:
            return []
        reason = f"its step was played again as {first.session} before its end was journaled; {first.session} counts"
        self.append(j.SessionMarkedInvalid(session=g.session, participant=g.participant, reason=reason))
        return [f"{g.session}: marked invalid: {reason}"]

    def unended_note(self, g: Game) -> str:
        """What the next serve, pilot or report does with game `g`, journaled as started and never as ended, in
        words for `protocol status` (which reads beside a writer and writes nothing): "" if it is running (a live
        recorder writes it) or `g` has ended. Status showed such a game's step as open, no word of its recording
        (a new user's trial)."""
        if g.ended is not None or is_live(self.folder / g.recording):
            return ""
        path, copy = self.game_recording(g)
        head = f"{g.session}: its end is not journaled"
        if path.is_file() and not wal_path(path).exists() and _finished_game(path) \
                and not self._not_this_games_file(g, path):
            return f"{head}; {copy or 'its recording'} holds it: the next serve, pilot or report journals it"
        if (cut := self._cut(g, path)) is not None:
            return f"{head}; the next serve, pilot or report journals it {cut.outcome}{self._cut_words(g, copy, cut)}"
        if self._never_recorded(g):
            return (f"{head}; {NEVER_RECORDED}: the next serve, pilot or report journals it aborted, and its step "
                    "is played again")
        if path.is_file() and (other := self._not_this_games_file(g, path)):
            return f"{head}; {copy or f'its recording {g.recording}'} is not this game's ({other}): move it away"
        return f"{head}; its recording {g.recording} is missing"

    def _never_recorded(self, g: Game) -> bool:
        """Whether game `g`, journaled as started and never as ended, was stopped before its recording began: no
        recording, no recorder's journal, no copy of one (a cut-short --force's, recover's), and not started by
        this object (a game it runs has its GameStarted journaled before its recorder starts). No other process
        runs a game of the folder while this one writes it (pairplay/folderlock.py), so nothing will record it:
        a second signal as `protocol serve` stopped it before then left it "running" for ever (a new user's trial)."""
        path = self.folder / g.recording
        return g.session not in self._started_here and not path.exists() and not wal_path(path).exists() \
            and not default_output(path).exists() and not set_aside_of(path)

    # -- derived tables ------------------------------------------------------
    def answers(self) -> list[dict]:
        """Every questionnaire answer of every recorded game, one row per item (`lost` ""), and a row for
        each answer its recording lost (`lost_answers`: item and answer empty, `lost` says why, in the
        reader's words): a QuestionnaireAnswered that does not decode was left out with no word."""
        rows = []
        for g in self.state.games.values():
            path, _ = self.game_recording(g)
            if not path.is_file():
                continue
            # the answers and the session's start kept as the file is read, nothing else (reader.events_of)
            log, kept = events_of(path, tags=frozenset({"SessionStarted", "QuestionnaireAnswered"}))
            started = [e for e in kept if type(e).__name__ == "SessionStarted"]
            if started and self.not_this_game(g, started[0].config):  # another session's answers are not its
                continue  # participant's (a `session --force` over a study game's recording)
            row = {"participant": g.participant, "phase": g.phase, "game": g.game + 1, "session": g.session,
                   "returning": int(self.returning(g.participant, g.phase)), "valid": int(not g.invalid),
                   "scripted": g.scripted}
            answered = [e for e in kept if type(e).__name__ == "QuestionnaireAnswered"]
            for e in answered:
                for item, answer in e.answers.items():
                    rows.append(row | {"questionnaire": e.questionnaire, "item": item, "answer": answer, "lost": ""})
            phase = self.study.phase_by_id(g.phase)
            asked = phase.questionnaires[0] if phase.questionnaires else ""
            for why in lost_answers(log, bool(answered), g.ended is not None and g.ended.questionnaire):
                rows.append(row | {"questionnaire": asked, "item": "", "answer": "", "lost": why})
        return rows

    def write_tables(self) -> list[Path]:
        """participants.csv, sessions.csv and answers.csv, rewritten from the journal and recordings."""
        with self._writing():
            tables = {
                # scripted: the personas that played a participant's games instead of a person (a rehearsal)
                # consent: when a person's informed consent was given ("" if not recorded) and to which form
                "participants.csv": (["participant", "joins", "registered_utc", "scripted", "consent_utc",
                                      "consent_form", "consent_recorded_utc"],
                                     [[pid, r.joins, _utc(r.time_ns), self.scripted_as(pid),
                                       *self.consent_cells(pid)]
                                      for pid, r in self.state.participants.items()]),
                # bias_flawed: the bias policy it was played on was made with a game marked invalid since
                # (replay/biases.py: the game stays valid; said wherever its bias policy is named)
                "sessions.csv": (["session", "participant", "phase", "game", "outcome", "reason", "rounds_played",
                                  "invalid", "recording", "policy", "bias", "scripted", "bias_flawed"],
                                 [[g.session, g.participant, g.phase, g.game + 1,
                                   g.ended.outcome if g.ended else "running", g.ended.reason if g.ended else "",
                                   g.ended.rounds_played if g.ended else 0, g.invalid, g.recording,
                                   g.ended.policy if g.ended else "", g.bias, g.scripted, self.bias_flaw(g)]
                                  for g in self.state.games.values()]),
            }
            answers = self.answers()
            # scripted: a persona's answers, not a person's (a new user's trial had to join on sessions.csv)
            # lost: an answer its recording lost (damage), said in the row that stands for it (`lost_answers`)
            cols = ["participant", "phase", "game", "session", "questionnaire", "item", "answer", "returning", "valid",
                    "scripted", "lost"]
            tables["answers.csv"] = (cols, [[r[c] for c in cols] for r in answers])
            paths = []
            for name, (head, rows) in tables.items():
                buf = io.StringIO()
                w = csvcell.writer(buf)  # answers are what people typed: never a formula
                w.writerow(head)
                w.writerows(rows)
                atomic_write(self.folder / name, buf.getvalue().encode())
                paths.append(self.folder / name)
            return paths

    def consent_cells(self, pid: str) -> list[str]:
        """[when consent was given (UTC), the form's version, when it was recorded (UTC)] of `pid`'s last
        consent recorded, ["", "", ""] if none."""
        c = self.state.consent.get(pid)
        return [_utc(c.given_ns or c.time_ns), c.form, _utc(c.time_ns)] if c is not None else ["", "", ""]

    # -- export and deletion -------------------------------------------------
    def files_of(self, pid: str) -> list[Path]:
        """Every file of the folder that holds `pid`'s data (recordings and their journals, policies, exports); a
        pipe, a device or a socket standing at one of their names too (a deletion removes it, an export refuses it:
        it was left out of the export silently, and reading it would have blocked)."""
        self.participant(pid)
        files = []
        for g in self.games_of(pid):
            files.append(self.folder / g.recording)
            files.append(wal_path(self.folder / g.recording))  # a killed recorder's journal: their data too
            files.append(default_output(self.folder / g.recording))  # recover's copy: it stands for a cut one
            # a policy built from their game whose line a killed process did not write (journaled_or_removed)
            files += list((self.folder / "policies").glob(f"{g.session}.*"))
            files += set_aside_of(self.folder / g.recording)  # an earlier recording a cut-short --force set aside
            if g.ended is not None and g.ended.policy:
                files.append(self.folder / g.ended.policy)
        files += list((self.folder / "exports").glob(f"{pid}.zip"))
        # a journal line of theirs a crash cut, set aside by `protocol repair` (replay/studyjournal.py)
        named = [f'"{pid}"'.encode()] + [f'"{g.session}"'.encode() for g in self.games_of(pid)]
        for torn in self.folder.glob(f"{JOURNAL}{studyjournal.TORN}-*"):
            if torn.is_file() and any(n in torn.read_bytes() for n in named):
                files.append(torn)
        return [f for f in dict.fromkeys(files) if f.is_file() or refusal(f)]

    def bias_flaw(self, g: Game) -> str:
        """What is wrong with the bias policy game `g` was played on ("" if nothing, or none): replay/biases.py."""
        c = biases.bias_of(self.state, g)
        return biases.flaw_words(self.state, c) if c is not None else ""

    def merged_using(self, pid: str) -> list[str]:
        """The merged policies combined from `pid`'s games (an earlier bias policy, kept for the record, too)."""
        mine = {g.ended.policy for g in self.games_of(pid) if g.ended is not None and g.ended.policy}
        return [c.output for c in self.state.combinations if mine & set(c.inputs)]

    def export_participant(self, pid: str, out: str | Path | None = None, force: bool = False,
                           left_out: list[str] | None = None) -> Path:
        """One zip of `pid`'s recordings, policies, answers and journal lines, with a README. A running game's
        files (`running`: its recording half-written, without its footer) are left out, and said in the README
        and by the sessions appended to `left_out`."""
        with self._writing():
            self.participant(pid)
            out = Path(out) if out else self.folder / "exports" / f"{pid}.zip"
            inside = out.resolve().relative_to(self.folder).parts if out.resolve().is_relative_to(self.folder) else ()
            if out.exists() and inside and inside[0] != "exports":  # -o study/journal.jsonl --force replaced it
                raise StudyDataError("a file of the study folder; an export never replaces one, --force or not: "
                                     "give another -o", out)
            if inside and inside != ("exports", f"{pid}.zip"):  # -o study/recordings/: a copy delete never found
                raise StudyDataError(f"inside the study folder an export goes only to "
                                     f"{self.given / 'exports' / f'{pid}.zip'} (erased with the participant): give no "
                                     "-o, or a path outside the study folder", out)
            # a folder (it said "exists (use --force to replace it)", and --force then said it is a folder), an
            # existing file without --force: refused in every output's words (`exists; --force replaces it (<path>)`)
            try:
                check_output(out, force)
            except OutputError as err:
                raise StudyDataError(err.what, err.where, fix=err.fix, option=err.option) from None
            games = self.games_of(pid)
            answers = [r for r in self.answers() if r["participant"] == pid]
            lines = [e for e in self.read_journal() if getattr(e, "participant", None) == pid]
            running = [g.session for g in games if self.running(g)]  # (an export during a game shipped its
            # half-written recording and the recorder's journal, the README calling it the game's every event)
            files = [f for f in self.files_of(pid) if f.parent.name != "exports"
                     and not any(f.name.startswith(f"{session}.") for session in running)]
            if left_out is not None:
                left_out += running
            for f in files:  # before the zip opens one: a pipe blocked it (pairplay/inputs.py)
                if said := refusal(f):
                    raise StudyDataError(f"{pid}'s data cannot be exported whole: {said}",
                                         self.given / f.relative_to(self.folder))
            buf = io.BytesIO()
            with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
                for f in files:
                    z.write(f, f.relative_to(self.folder).as_posix())
                cols = ["participant", "phase", "game", "session", "questionnaire", "item", "answer", "lost"]
                text = io.StringIO()
                w = csvcell.writer(text)
                w.writerow(cols)
                w.writerows([[r[c] for c in cols] for r in answers])
                z.writestr("answers.csv", text.getvalue())
                # their row of participants.csv: registration and consent (when given, to which form)
                text = io.StringIO()
                w = csvcell.writer(text)
                w.writerow(["participant", "joins", "registered_utc", "consent_utc", "consent_form", "consent_recorded_utc"])
                w.writerow([pid, self.state.participants[pid].joins, _utc(self.state.participants[pid].time_ns),
                            *self.consent_cells(pid)])
                z.writestr("participant.csv", text.getvalue())
                z.writestr("journal.jsonl", b"".join(j.encode_line(e) for e in lines))
                z.writestr("README.txt", _export_readme(pid, self.study.study.id, games, files, answers,
                                                        self.merged_using(pid), self.folder,
                                                        self.state.consent.get(pid)))
            # with the verb's --force only: a file put there while the zip was made is not replaced either
            atomic_write(out, buf.getvalue(), force)
            # where it went and what it wrote, so that their deletion erases it while it is this file unchanged, and
            # names it otherwise (a copy handed on is beyond its reach)
            try:
                self.append(j.ParticipantExported(participant=pid, path=str(out.resolve()),
                                                  sha256=hashlib.sha256(buf.getvalue()).hexdigest()))
            except BaseException as err:  # (a full disk, a signal) no export their deletion would not know is left
                out.unlink(missing_ok=True)
                if not isinstance(err, Exception):
                    raise
                raise StudyDataError(f"{one_line(err)}; the export {out} was removed: its journal line could not be "
                                     "written (their deletion would not know it)") from None
            return out

    def delete_participant(self, pid: str, consent_withdrawn: bool = False) -> "Deletion":
        """Erase `pid` everywhere pairplay put their data (see the module rule); the deletion is journaled
        without their id. Refused while one of their games is running. The copies journaled beyond the folder's
        own places (an export outside it, a verb's output: `copies_of`) are erased if still pairplay's unchanged
        files. What it did with them, and what it could not erase (a changed or moved copy, the files of report/
        the report did not write: a user's notes may name them), is returned to be said. `consent_withdrawn`: the
        person withdrew their consent: the anonymous line says so (their ConsentGiven goes with their lines);
        refused for a person whose consent was never recorded (nothing journaled to withdraw: the line would say a
        consent the journal never held; a consent held on paper is recorded first, `record_consent(given_ns=)`)."""
        with self._writing():
            self.participant(pid)
            if consent_withdrawn and pid not in self.state.consent:
                raise StudyDataError(f"{pid} has no consent recorded: there is none to withdraw (delete without "
                                     "--consent-withdrawn, or first record the consent they gave on paper: "
                                     f"`pairplay protocol consent {command_word(self.given)} {command_word(pid)} "
                                     "--given-at ISO-TIME`)")
            # Running is what this process started and has not ended: holding the folder's writer lock (one writer
            # per study folder), no other process can be running a game of it, so a game journaled as started
            # and never ended was the game of a process that died (SIGKILL, a power cut) and is deleted with the
            # rest. It was "running" for ever: nothing could end it, and the participant could not be erased.
            running = [g.session for g in self.games_of(pid) if self.running(g)]
            if running:
                raise StudyDataError(f"{pid} has a game running ({running[0]}): abort it first", self.given)
            merged = self.merged_using(pid)
            flaws = biases.flaws_of(self.state, pid)  # the flaw, not the mark's words (biases.py rule)
            files = self.files_of(pid)
            sessions = {g.session for g in self.games_of(pid)}
            live = [f for f in files + [x for g in sessions for x in (self.folder / "recordings").glob(f"{g}.*")]
                    if is_live(f)]
            if live:  # its recorder still writes it (a game's questionnaire holds it open): pairplay/livelock.py
                # named as given (the study folder as typed), not resolved
                raise StudyDataError(f"{pid}: {self.given / live[0].relative_to(self.folder)} {LIVE}: stop its "
                                     "session first")
            key = self.key_file
            if key is not None and not key.is_file() and not refusal(key):  # before anything is deleted: their
                # name stays in it (a pipe there is refused for what it is, by key_file_ids)
                # (a folder at its path was "not there", trial36 K1)
                there, fix = (("is a folder, not the key file", "put the key file back there first") if key.is_dir()
                              else ("is not there (an unmounted drive?)", "make it reachable first"))
                raise StudyDataError(f"{pid}: the key file {key} {there}: their name would stay in it; {fix}, "
                                     "then delete")
            lines = self.key_file_ids().count(pid)
            # their name, as the key file holds it: a kept line of another's that wrote it (a mark's reason, "Anna
            # Schmidt's mother came in") keeps it no more than their id (trial33 C: the key file's line went, the
            # journal kept the name)
            name = self._key_name(pid) if lines == 1 else ""
            if lines > 1:  # an id given twice (a crash, a torn registration, before ids_on_record): two people
                raise StudyDataError(f"{pid}: the key file {key} holds {counted(lines, 'line')} for this id (it was given "
                                     "twice after a crash); nothing was deleted, since it would erase both people: "
                                     "find whose data this is, give the other line a note by hand, then delete")
            for f in files:
                f.unlink()
            for g in sessions:  # anything else a tool wrote next to the recording (e.g. a view's .rrd)
                for extra in (self.folder / "recordings").glob(f"{g}.*"):
                    extra.unlink()
                    files.append(extra)
            # the copies of their data journaled beyond the places above (an export -o elsewhere, a verb's output:
            # replay/copies.py): each erased if still pairplay's unchanged file, else named
            copies = [_settle(e, {f.resolve() for f in files}) for e in self.copies_of(pid)]
            erased = {c.path for c in copies if c.erased}
            _tidy_manifests({Path(c.path).parent for c in copies if c.erased})
            kept, removed, unnamed = [], 0, 0
            for e in self.read_journal():
                if getattr(e, "participant", None) == pid or getattr(e, "session", None) in sessions:
                    removed += 1
                elif isinstance(e, j.CopyWritten) and pid in e.participants:
                    # a copy erased now, or of their data alone, goes; one of others' data too stays theirs
                    others = [p for p in e.participants if p != pid]
                    if e.path in erased or not others:
                        removed += 1
                    else:
                        kept.append(_redacted(msgspec.structs.replace(e, participants=others), pid))
                else:  # a combination of their games, a note naming them: kept without the id
                    line = _redacted(_withheld(e), pid)
                    kept.append(_unnamed(line, name))
                    unnamed += kept[-1] is not line
            for m in merged:
                _redact_policy_file(self.folder / m, pid)
            key_removed = self._drop_from_key_file(pid)
            atomic_write(self.folder / JOURNAL, b"".join(j.encode_line(e) for e in kept))
            self._stamp = self._journal_stamp()  # ours: the append below writes on it
            state = StudyState()
            for e in kept:
                state.evolve(e)
            self.state = state
            # derived files that held their rows: the tables are rewritten, the report's files are removed (it
            # is stale without them); a file of the user's in report/ (notes.md) stays, and is said
            report = self.folder / "report"
            left = [(f"report/{rel}", _names(report / rel, pid, name))
                    for rel in remove_written(report, REPORT_OUTPUTS, REPORT_MANIFEST)]
            deleted = self.append(j.ParticipantDeleted(
                deletion=secrets.token_hex(6), sessions_removed=len(sessions), files_removed=len(files),
                journal_lines_removed=removed, merged_policies_using_them=merged, key_file_line_removed=key_removed,
                copies_erased=len(erased), consent_withdrawn=consent_withdrawn, flaws_kept=flaws))
            self.write_tables()
            return Deletion(deleted, left, [c for c in copies if c.fate], unnamed,
                            str(key) if key is not None and lines == 0 else "")

    def copies_of(self, pid: str) -> list[j.ParticipantExported | j.CopyWritten]:
        """The copies of `pid`'s data the journal says were made beyond the places their deletion erases by
        itself: exports outside the folder (ParticipantExported), verbs' outputs (CopyWritten); for a path written
        more than once, its last writing, if that holds their data (an earlier one was replaced by it)."""
        last: dict[str, j.ParticipantExported | j.CopyWritten] = {}
        for e in self.read_journal():
            if isinstance(e, (j.ParticipantExported, j.CopyWritten)):
                last[e.path] = e
        return [e for e in last.values()
                if (isinstance(e, j.ParticipantExported) and e.participant == pid
                    and not Path(e.path).is_relative_to(self.folder))
                or (isinstance(e, j.CopyWritten) and pid in e.participants)]

    def _key_name(self, pid: str) -> str:
        """The name this study's line of the key file gives `pid` ("" without one)."""
        key = self.key_file
        if key is None or not key.is_file():
            return ""
        return next((csvcell.value(r[1]) for r in key_file_rows(key) if r[0] == pid and len(r) > 1
                     and self._own_key_line(r)), "")

    def _drop_from_key_file(self, pid: str) -> bool:
        key = self.key_file
        if key is None or not key.is_file():
            return False
        rows = key_file_rows(key, header=True)  # its header stays: the file is still the study's
        kept = [r for n, r in enumerate(rows) if r[0] != pid or not self._own_key_line(r)
                or (n == 0 and is_key_header(r))]  # another study's p01 is not theirs
        if len(kept) == len(rows):
            return False
        buf = io.StringIO()
        csv.writer(buf).writerows(kept)  # the rows as read: their cells are written already (csvcell)
        with output_file(key, "wb", force=True) as f:  # atomic_write's way, owner-only before it is renamed
            os.fchmod(f.fileno(), KEY_FILE_MODE)
            f.write(buf.getvalue().encode("utf-8"))
            f.flush()
            os.fsync(f.fileno())
        return True


@dataclass(frozen=True)
class Copy:
    """What a deletion did with one journaled copy of the participant's data (`copies_of`): `fate` "erased"
    (pairplay's own file, unchanged: the bytes it wrote, at the path it wrote them), "changed" (other bytes
    there now, or no longer a plain file), "missing" (not there now), "unverifiable" (journaled without its
    SHA-256, by an older pairplay), "unreadable: <why>", "not erased: <why>" (removing it failed)."""

    path: str
    verb: str  # "participant export", or the verb that wrote it
    fate: str

    @property
    def erased(self) -> bool:
        return self.fate == "erased"


def _settle(e: j.ParticipantExported | j.CopyWritten, removed: set[Path]) -> Copy:
    """Erase the journaled copy `e` if it is still pairplay's own, unchanged file (its SHA-256 is the journaled
    one); say what it is otherwise. A file the deletion removed already (`removed`: in the folder) is fate ""."""
    verb = "participant export" if isinstance(e, j.ParticipantExported) else e.verb
    path = Path(e.path)
    if not path.exists() and not path.is_symlink():
        return Copy(e.path, verb, "" if path in removed else "missing")
    if path.is_symlink() or not path.is_file() or is_live(path):  # not the file pairplay wrote there
        return Copy(e.path, verb, "changed")
    if not e.sha256:
        return Copy(e.path, verb, "unverifiable")
    try:
        same = sha256_of(path) == e.sha256
    except OSError as err:
        return Copy(e.path, verb, f"unreadable: {err.strerror or err}")
    if not same:
        return Copy(e.path, verb, "changed")
    try:
        path.unlink()
    except OSError as err:
        return Copy(e.path, verb, f"not erased: {err.strerror or err}")
    return Copy(e.path, verb, "erased")


def _tidy_manifests(folders: set[Path]) -> None:
    """In each folder a deletion erased copies from: a verb's manifest there (pairplay/outputs.py) no longer lists
    them (it named the files, the participant's id in a session's name among them), and goes when it lists
    nothing more, with the folder if that leaves it empty. Best effort: what cannot be tidied stays as it is."""
    for folder in folders:
        for manifest in folder.glob(manifest_name("*")):
            listed = read_manifest(manifest)
            there = [f for f in listed if (folder / f).is_file()]
            if there == listed:
                continue
            try:
                if there:
                    write_manifest(manifest, there)
                else:
                    manifest.unlink()
            except OSError:
                pass
        try:
            folder.rmdir()  # only an empty one goes
        except OSError:
            pass


def sha256_of(path: Path) -> str:
    """The SHA-256 of the file `path` (hex), read in blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@dataclass(frozen=True)
class Deletion:
    """What `delete_participant` did (`event`, journaled without the id) and what it could not erase, to be
    said: files of report/ the report did not write (`left`: relative path, whether it names the id) and the
    copies the journal names beyond the folder's own places (`copies`: exports outside the folder, verbs'
    outputs), each erased or not, and why."""

    event: j.ParticipantDeleted
    left: list[tuple[str, bool]]
    copies: list[Copy]
    unnamed: int = 0  # kept lines of others whose reason named them (`_unnamed`): their name replaced, said
    # the study's key file, when it holds no line of theirs (a hand edit): their name is unknown, so no kept text
    # was checked for it; said (trial35 D2: nothing was)
    no_key_line: str = ""

    @property
    def elsewhere(self) -> list[str]:
        """The copies not erased (absolute paths)."""
        return [c.path for c in self.copies if not c.erased]


def _names(path: Path, pid: str, name: str = "") -> bool:
    """Whether the file `path` holds the id `pid` as a whole id, or their `name` (`_name_pattern`) (its bytes;
    a figure's pixels cannot tell)."""
    try:
        text = path.read_bytes()
    except OSError:
        return False
    pattern = _name_pattern(name)
    return re.search(_id(pid).encode(), text) is not None or (
        pattern is not None and re.search(pattern, text.decode("utf-8", "replace"), re.IGNORECASE) is not None)


def _name_pattern(name: str) -> str | None:
    """A pattern of a person's `name` (from the key file) in free text, in any case: the whole name, its parts
    joined by a space, hyphen, dot, underscore or nothing ("Anna-Schmidt", "annaschmidt@uni.de"), or any part
    of two letters or more alone ("Anna's mother", "A. Schmidt", "the Schmidts"), each as whole words; None for
    a name with no such part (one letter would find every "a"). An experimenter writes "Anna's mother", not
    "Anna Schmidt's mother": matching the whole name alone left a first name and a surname that still said
    who the deleted person was (trial34 D). A part that is also a word ("May") is taken too: erring towards
    erasure."""
    # a name in a script written without spaces (Chinese, Japanese): "王伟的妈妈来了" has no word boundary around 王伟,
    # and "李 娜" no part of two letters; such a name is found anywhere in the text, whole (its spaces dropped) or
    # by each word of two characters or more (trial36 D4)
    unspaced = [w for w in ("".join(name.split()), *name.split()) if len(w) >= 2 and _unspaced_script(w)]
    anywhere = "|".join(map(re.escape, sorted(set(unspaced), key=len, reverse=True)))
    parts = [w for w in re.findall(r"[^\W\d_]+", name) if len(w) >= 2]
    if not parts:
        return anywhere or None
    # joined over every spelling of each part ("juergenmueller@uni.de" as "Anna-Schmidt": trial36 D3)
    joined = r"[\s\-._]*".join("(?:" + "|".join(map(re.escape, sorted(_spellings(w), key=len, reverse=True))) + ")"
                                 for w in parts)
    # and as an English keyboard writes them (trial35 D1: "Mueller", "Jurgen", "Zoe", "OBrien" stayed): each word
    # without its apostrophes and hyphens, each part in every spelling `_spellings` gives
    words = [v for w in name.split() for v in (w, w.replace("'", "\u2019"), w.replace("\u2019", "'"),
                                               re.sub(r"['\u2019\-]", "", w))]
    forms = {f for w in parts + [w for w in words if len(w) >= 2] for f in _spellings(w)}
    alone = "|".join(map(re.escape, sorted(forms, key=len, reverse=True)))
    bounded = rf"(?<![^\W_])(?:{joined}|{alone})s?(?![^\W_])"  # an underscore parts words here ("Schmidt_Anna")
    return f"{anywhere}|{bounded}" if anywhere else bounded


def _unspaced_script(word: str) -> bool:
    """Whether `word` holds a letter of a script written without spaces between words (Han, Hiragana, Katakana)."""
    import unicodedata
    return any(unicodedata.name(c, "").startswith(("CJK UNIFIED", "CJK COMPATIBILITY", "HIRAGANA", "KATAKANA"))
               for c in word)


# letters as a keyboard without them writes them (`_spellings`): NFKD leaves these whole (no combining mark to drop), so
# "Søndergård" stayed "Søndergard" and "Łukasz" never became "Lukasz" (trial36 D3); and each spelled out, as German
# and the Nordic languages write them without the letter ("Mueller", "Soendergaard")
KEYBOARD_LETTERS = {"ø": "o", "ł": "l", "æ": "ae", "œ": "oe", "đ": "d", "þ": "th", "ı": "i", "ß": "ss"}
SPELLED_OUT = {"ä": "ae", "ö": "oe", "ü": "ue", "ø": "oe", "å": "aa", "æ": "ae", "œ": "oe", "ß": "ss", "ł": "l",
               "đ": "d", "þ": "th", "ı": "i"}


def _spellings(word: str) -> set[str]:
    """`word` (lower case: the pattern ignores case) as written, without its accents and with the letters NFKD
    keeps whole written plainly ("zoë" -> "zoe", "müller" -> "muller", "søndergård" -> "sondergard"), with umlauts
    and Nordic letters spelled out ("mueller", "soendergaard", "strasse"), and in every mix of these."""
    import unicodedata

    def unmarked(text: str) -> str:
        return "".join(c for c in unicodedata.normalize("NFKD", text) if not unicodedata.combining(c))
    import itertools
    # each letter as written, plainly, or spelled out, in every mix ("sondergaard": ø plain, å spelled out); a
    # name's letters with more than one way are few, and past 6 of them only the three whole ways are taken
    ways = [sorted({c, "".join(KEYBOARD_LETTERS.get(u, u) for u in unmarked(c)), unmarked(SPELLED_OUT.get(c, c))})
            for c in word.lower()]
    if sum(len(w) > 1 for w in ways) > 6:
        return {"".join(w[i] if len(w) > i else w[0] for w in ways) for i in range(3)}
    return {"".join(mix) for mix in itertools.product(*ways)}


def mentions(text: str, pid: str) -> bool:
    """Whether `text` holds the id `pid` as a whole id (p01 is not in p010)."""
    return re.search(_id(pid), text) is not None


API_WRITE = "a write through pairplay's Python API"  # the holder's words of a StudyData made without a writer


def _take_lock(folder: Path, given: Path, verb: str) -> int | None:
    """The study folder's writer lock for `verb` (pairplay/folderlock.py: a short holder waited for, saying so
    on stderr); StudyDataError naming the holder."""
    waiting = folderlock.say_waiting(verb, given) if verb != API_WRITE else (  # a library's words: logged
        lambda who: logging.getLogger("pairplay.studydata").warning("%s", folderlock.waiting_line(who, given)))
    try:
        return folderlock.take(folder, verb, folderlock.WAIT_S, waiting)
    except folderlock.FolderBusy as busy:
        who = busy.holder or "a process"
        if folderlock.is_long(busy.holder):  # serve has a console to work in; a pilot none: it ends by itself
            fix = ("wait for it to end, or stop it" if busy.holder.startswith("protocol pilot")
                   else "stop it, or work in its console")
            raise StudyDataError(f"another pairplay writes this study folder: {who}; one writer per study folder: "
                                 f"{fix} (`pairplay protocol status` reads beside it)", given) from None
        raise StudyDataError(f"another pairplay writes this study folder: {who}; waited {folderlock.WAIT_S:g} s "
                             "for it to finish (one writer per study folder): run this again when it has", given) from None


def not_a_study_folder(given: Path) -> StudyDataError:
    """The refusal of a study folder argument that is none: a file said as a file (a study TOML given for its
    folder was "not a study folder (no journal.jsonl ...)", `report FILE` "cannot write there"), with the verb
    that makes a folder of it."""
    if given.is_file():
        made = f"`pairplay protocol init FOLDER --study {command_word(given)}` makes one of it" if given.suffix == ".toml" else \
            "give the folder `pairplay protocol init` made"
        return StudyDataError(f"{given}: a file, not a study folder: {made}")
    return StudyDataError(f"{given}: not a study folder (no {JOURNAL}; `pairplay protocol init` makes one)")


def repair_journal(folder: str | Path) -> studyjournal.Repaired:
    """`pairplay protocol repair`: the journal's last line a crash cut set aside beside it, under the folder's
    writer lock (replay/studyjournal.py), the tables (participants.csv...) and the manifest then written again
    from the journal left; StudyDataError if it is no study folder or a line that is not the torn last one is
    damaged (nothing changed then)."""
    given = Path(folder)
    resolved = given.resolve()
    if not (resolved / JOURNAL).is_file():
        raise not_a_study_folder(given)
    fd = _take_lock(resolved, given, "protocol repair")
    try:
        try:
            done = studyjournal.repair(resolved / JOURNAL, given / JOURNAL, given)
        except studyjournal.JournalDamaged as err:
            raise StudyDataError(str(err)) from None
        if done.aside is not None:  # the tables and manifest said what the line set aside held (a consent): they
            held, fd = fd, None     # are written again from the journal as it is now, under the same lock
            with StudyData(given, study_file_edited_ok=True, held=held) as data:
                data.write_tables()
                data.write_folder_manifest()
        return done
    finally:
        folderlock.release(fd)


class FolderSettings(msgspec.Struct, forbid_unknown_fields=True):
    """settings.json: where the key file is ("" for none)."""

    key_file: str = ""


def _settings(path: Path) -> dict:
    """settings.json as a dict ({} without one); StudyDataError, one line naming it, if it is not what
    `create` writes (a list, a number where the key file's path goes: `participant delete` crashed halfway,
    its files gone and its journal lines kept, a new user's trial)."""
    if not path.is_file():
        return {}
    data = without_bom(path.read_bytes())
    try:
        refuse_repeated(data)  # a key given twice: msgspec would keep the last, silently
        return msgspec.structs.asdict(json_decode(data, type=FolderSettings))
    except (msgspec.DecodeError, msgspec.ValidationError) as err:
        raise StudyDataError(f"not the study's settings: {in_words(err, FolderSettings, data)}; it is "
                             f"{{\"key_file\": \"<path or empty>\"}}", path) from None


def game_end(folder: Path, session: str, participant: str, path: Path, answered: bool | None = None,
             abort_reason: str = "", force: bool = False) -> j.GameEnded:
    """How a game ended, from its finished recording: completed or aborted (the reason its SessionEnded
    gives, else `abort_reason`), its whole rounds and their policy (written to <folder>/policies, none
    for a game stopped in round 1), whether the questionnaire was answered (`answered`, else whether
    the recording holds the answers, one that does not decode included: answers.csv says it was lost).
    A recording that lost events (`recording_damage`) gives no policy, as `build_missing_policies`
    refuses one (the game's Q-table is not what the file holds), and the damage is the GameEnded's
    reason, in the reader's words; a completed game keeps its outcome (the next start's
    build_missing_policies says again why it has no policy; the combination refuses to go without it).
    Before, a partial policy was written and journaled as the game's, with no word."""
    recorded, summed = fold_log(path, None, Summed)  # summed up as it is read, nothing of it kept (fold.Summed)
    fold = summed.fold
    ended = fold.ended
    completed = ended is not None and ended.reason == "completed"
    damaged = recording_damage(recorded)
    policy = ""
    if fold.config is not None and fold.whole_rounds() and not damaged:  # a game stopped in round 1: no policy
        policy = write_game_policy(folder, rebuild_recording(path), force=force)
    reason = "" if completed else (f"{ended.reason}: {ended.detail}" if ended is not None and ended.detail else
                                   ended.reason if ended is not None else abort_reason or "the game did not end")
    if damaged:
        reason = "; ".join(r for r in (reason, f"recording {damaged}: no policy built") if r)
    if answered is None:
        answered = summed.answered or bool(lost_answers(recorded, False, False))
    return j.GameEnded(session=session, participant=participant, outcome="completed" if completed else "aborted",
                       reason=reason, rounds_played=len(fold.whole_rounds()), policy=policy, questionnaire=answered)


def recording_damage(log) -> str:
    """What a game's finished recording (reader.EventLog) lost, in the reader's words ("" if nothing):
    "damaged: ..." for events lost (`EventLog.lost`: a damaged part that held some, messages that do not
    decode) or "truncated: ..." for a cut (a finished file that stops early lost its end). A damage that
    lost no event (a summary's CRC), or a cut after the data section's end, is not a loss, as for rebuild."""
    if log.lost:
        return f"damaged: {log.lost}"
    # (a recovered copy of a cut file lost its source's end: reader.EventLog.source_cut)
    return f"truncated: {log.brief}" if log.cut_lost else log.source_cut


def lost_answers(log, decoded: bool, journaled: bool) -> list[str]:
    """Why each questionnaire answer a read recording (reader.EventLog) lost is missing, one line each ([] if
    none): a QuestionnaireAnswered message that does not decode (or one on no channel: it may be one), in the
    reader's words; and, when no answer decoded but the journal says the game's questionnaire was answered
    (`journaled`), a damaged part that lost events (`EventLog.brief`) or the file's cut: the answers may have
    been in it. A game's answers are one message, so one that decoded leaves nothing else to lose."""
    if decoded:
        return []
    bad = [b for b in log.bad if b.key.rsplit("/", 1)[-1] in ("QuestionnaireAnswered", "")]
    if bad:
        return [f"the answers do not decode ({b.key or 'no channel'}: {b.reason[:80]})" for b in bad]
    if journaled and (log.lost_from >= 0 or log.cut_lost):  # (a recovered file's source's losses: `lost`)
        return [f"answered (the journal says), not in the recording: "
                f"{recording_damage(log)}"]
    return []


def _finished_game(path: Path) -> bool:
    """Is the recording whole and does it hold its game's end?"""
    try:
        # its ends kept as it is read, nothing else (reader.events_of)
        recorded, ends = events_of(path, only=frozenset({"SessionStarted", "SessionEnded"}),
                                   tags=frozenset({"SessionEnded"}))
    except (InputError, OSError):
        return False
    return recorded.whole and bool(ends)


def write_game_policy(folder: Path, rebuilt: Rebuilt, force: bool = False) -> str:
    """A game's rebuilt policy written to <folder>/policies (its learning curve is in the recording and
    the report: not written); returns its path relative to `folder`. A file already there is never replaced:
    with `force` (a build a kill may have cut before its journal line) one that is this build's to the byte is
    taken as it is (the killed build's, written whole: pairplay/outputs.py), any other refused by name. Before,
    `force` replaced whatever was there, and the curve written beside it (with force) and then removed took
    a researcher's <session>.curve.csv (`pairplay rebuild` writes one) with it, without a word."""
    path = output_paths(rebuilt, folder / "policies")[0]
    data = encode_policy(rebuilt.policy)
    if force and os.path.lexists(path):
        if not (path.is_file() and not path.is_symlink() and path.read_bytes() == data):
            raise OutputError("exists, not this game's policy as pairplay builds it: move it away", path)
    else:
        write_policy(path, rebuilt.policy)
    return path.relative_to(folder).as_posix()


def _line_numbers(lines: list[int]) -> str:
    """`lines 7, 9, 12` (the first few of them, `...` beyond): which lines of the journal a problem is on."""
    shown = ", ".join(map(str, lines[:5])) + (", ..." if len(lines) > 5 else "")
    return f"line {shown}" if len(lines) == 1 else f"lines {shown}"


def one_line(err: Exception) -> str:
    """An error as one line: a UserError's own line (its paths escaped, not folded), else its message
    with its newlines folded (a library's words)."""
    if isinstance(err, UserError):
        return err.line() if isinstance(err, (InputError, OutputError)) else str(err)
    return folded(err)


def _id(text_id: str) -> str:
    """A pattern of `text_id` as a whole id in a text (p01 is not in p010 nor in xp01)."""
    return rf"(?<![A-Za-z0-9]){re.escape(text_id)}(?![0-9])"


def named(text: str, names: dict[str, str]) -> str:
    """`text` (a combination's rule, "fewer-errors(human:p02+human:p03)") with each id of `names`
    replaced by its name (`StudyData.user_names`)."""
    if not names:
        return text
    pattern = "|".join(_id(i) for i in sorted(names, key=len, reverse=True))
    return re.sub(pattern, lambda m: names[m.group(0)], text)


def refuse_control(text: str, what: str, as_what: str, limit: int = 0) -> None:
    """The rule of every free text a study takes from the experimenter (a mark's, a pause's or an abort's reason,
    a name for the key file): one line, without a control character (a newline, a tab, a NUL, an ESC: each
    went raw into a CSV or the report) and, with a `limit`, at most that many characters once stripped; else
    StudyDataError saying which and where. A study file's texts are checked by schemas/study.py (ids, the
    consent form), a questionnaire's answers by services/protocol.py check_answers. What an older pairplay
    journaled unchecked is escaped where it is read (StudyState.evolve)."""
    if (bad := unshowable(text)) is not None:
        raise StudyDataError(f"{what} holds a control character ({bad.group()!r} at {bad.start()}): give "
                             f"{as_what} as one line of text, without tabs")
    if limit and len(text.strip()) > limit:
        raise StudyDataError(f"{what} is at most {counted(limit, 'character', spec=',')}, this one has {len(text.strip()):,}")


def _redact(text: str, pid: str) -> str:
    """`text` with the pseudonym `pid` (as an id, in `human:<id>` and in session names) replaced by "deleted"."""
    return re.sub(_id(pid), "deleted", text)


def _redacted(value, pid: str):
    """`value` with `pid` redacted (`_redact`) from every text it holds, at any depth: each string, list
    item, dict key and value, and field of a struct (a journal event, a policy file). Every field, not a
    list of the ones known to name people: a merged policy's per-state `rules` and a combination's
    `decided_by` ("fewer-errors(human:p02+human:p03)") kept the id when only users, inputs, participant
    and merged_from were redacted."""
    if isinstance(value, str):
        return _redact(value, pid)
    if isinstance(value, list):
        return [_redacted(v, pid) for v in value]
    if isinstance(value, dict):
        return {_redacted(k, pid): _redacted(v, pid) for k, v in value.items()}
    if isinstance(value, msgspec.Struct):
        return msgspec.structs.replace(value, **{f: _redacted(getattr(value, f), pid)
                                                 for f in value.__struct_fields__})
    return value


def _unnamed(e: j.JournalEvent, name: str) -> j.JournalEvent:
    """`e`, a line kept by a deletion, with `name` (the deleted person's, from the key file) replaced by "deleted"
    in its free text, the `reason` a person typed (another's game's mark or end: "Anna's mother came in"), in
    any case (`_name_pattern`: the name, its joined forms, its parts). Only there: a name may be any word
    ("phase1"), and the ids, phases and files the other fields hold are no one's words. `e` itself when its
    reason does not name them (the deletion counts the lines it rewrote, and says so)."""
    pattern, reason = _name_pattern(name), getattr(e, "reason", None)
    if pattern is None or not isinstance(reason, str):
        return e
    unnamed = re.sub(pattern, "deleted", reason, flags=re.IGNORECASE)
    return e if unnamed == reason else msgspec.structs.replace(e, reason=unnamed)


def _withheld(e: j.JournalEvent) -> j.JournalEvent:
    """`e`, an earlier deletion's line without the mark reasons an older pairplay kept in its flaws (the words
    about a person deleted then: replay/biases.py rule); any other line as it is."""
    if not isinstance(e, j.ParticipantDeleted) or all(k.reason == biases.WITHHELD for k in e.flaws_kept):
        return e
    return msgspec.structs.replace(e, flaws_kept=[msgspec.structs.replace(k, reason=biases.WITHHELD)
                                                  for k in e.flaws_kept])


def _redact_policy_file(path: Path, pid: str) -> None:
    """A merged policy file keeps its actions but names `pid` nowhere (`_redacted`)."""
    if not path.is_file():
        return
    write_policy(path, _redacted(read_policy(path), pid), force=True)  # the redaction replaces it


def _utc(ns: int) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(ns / 1e9)) if ns else ""


def consent_words(c: j.ConsentGiven) -> str:
    """A recorded consent in words: `form 'v2 2026-11' given 2026-12-03T10:00:00Z`, and `(recorded ...)` after
    it when it was given before it was recorded (`--given-at`)."""
    return ((f"form {c.form!r}" if c.form else "the study's form (its version not named)")
            + f" given {_utc(c.given_ns or c.time_ns)}" + (f" (recorded {_utc(c.time_ns)})" if c.given_ns else ""))


def _export_readme(pid: str, study: str, games: list[Game], files: list[Path], answers: list[dict],
                   merged: list[str], folder: Path, consent: j.ConsentGiven | None = None) -> str:
    lines = [f"Data of participant {pid} in study {study} (pairplay {__version__})", "",
             f"Informed consent: {consent_words(consent) if consent is not None else 'not recorded'}", "",
             "Everything pairplay holds about this pseudonymous participant:", ""]
    for g in games:
        status = g.ended.outcome if g.ended else \
            "running when exported: its files are left out (half-written); export again after its end"
        lines.append(f"- game {g.session}: phase {g.phase}, game {g.game + 1}, {status}"
                     + (f", marked invalid: {g.invalid}" if g.invalid else ""))
    lines += ["", "Files:", ""]
    for f in files:
        rel = f.relative_to(folder).as_posix()
        what = ("MCAP recording of every event of the game (JSON messages, JSON Schemas inside; "
                "open with any MCAP reader, e.g. `mcap cat`, Foxglove, or Python's mcap package)"
                if rel.endswith(".mcap") else
                "the recorder's write-ahead journal of that recording, left by a recorder that did not finish it "
                "(what it received, raw; `pairplay recover` adds it to the recording)"
                if rel.endswith(".journal") else
                "the policy learned in that game (JSON: Q-table 24 states x 88 actions, greedy action per state)")
        lines.append(f"- {rel}: {what}")
    lost = sum(1 for a in answers if a["lost"])
    lines += [f"- answers.csv: {counted(len(answers) - lost, 'questionnaire answer')} (one row per item)"
              + (f", and {counted(lost, 'row')} for answers a damaged recording lost (column `lost`: why)"
                 if lost else ""),
              "- participant.csv: their registration and informed consent (when given, to which form's version)",
              "- journal.jsonl: the study journal's lines about this participant (registration, consent, games, "
              "marks)", ""]
    if merged:
        lines += ["Merged policies combined from this participant's games (kept in the study; not included): "
                  + ", ".join(merged), ""]
    lines += ["Names are never stored with the data: the participant is known only by the id above."]
    return "\n".join(lines) + "\n"


def _ignored(recorded: list) -> None:
    """`StudyData.recording_of`'s fold when its caller folds nothing."""


class _Watched(tuple):
    """`StudyData.recording_of`'s fold: (check.RoundWatch, the caller's fold), both given each chunk's events."""

    def __new__(cls, fold):
        return super().__new__(cls, (RoundWatch(), fold))

    def __call__(self, recorded: list) -> None:
        self[0].take(r.event for r in recorded)
        self[1](recorded)

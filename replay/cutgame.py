"""How a study game ended, read from a recording that is not finished: what a second signal or a crash leaves.

Rule: a game journaled as started and never as ended (replay/studydata.py `build_missing_policies`) whose
recording is cut (its recorder's journal beside it, or the file without its end) ended as the game's own
`SessionEnded` says, found in the file or, when the file lacks it, in the recorder's journal beside it (the
journal holds every event the recorder received: replay/wal.py); no such event: the recording was cut before the
game's end, and the game is aborted (its step is played again). Read only: nothing is written here. A journal of
another session, or of another recording of the session id (replay/wal.py `not_its`), or one that cannot be read,
is not read (recover's own line names it).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pairplay.errors import InputError

from .fold import Summed
from .reader import fold_log
from .wal import RECORDER_METADATA, NotAJournal, not_its, read_journal, wal_path

CUT_BEFORE_END = "its recording was cut before the game's end"  # the GameEnded reason of such a game


@dataclass(frozen=True)
class CutEnd:
    """What a cut recording says of its game's end."""
    ended: object | None  # the game's SessionEnded (schemas/events.py), None if neither file nor journal holds it
    where: str  # "the file" or "its recorder's journal beside it": where `ended` was found ("" if not)
    rounds: int  # whole rounds played: the SessionEnded's count, else the file's whole rounds
    answered: bool  # the questionnaire's answers are in the file or the journal

    @property
    def outcome(self) -> str:
        return "completed" if self.ended is not None and self.ended.reason == "completed" else "aborted"

    @property
    def reason(self) -> str:
        """The GameEnded's reason: "" for a completed game, the SessionEnded's words, or CUT_BEFORE_END."""
        if self.ended is None:
            return CUT_BEFORE_END
        if self.ended.reason == "completed":
            return ""
        return f"{self.ended.reason}: {self.ended.detail}" if self.ended.detail else self.ended.reason


def cut_end(path: Path, journal_of: Path, session: str) -> CutEnd:
    """The end of game `session` as its cut recording `path` (the file its GameStarted names, or the copy `pairplay
    recover` wrote of it) and the recorder's journal beside `journal_of` (the file its GameStarted names) hold it
    (module rule). A file that cannot be read at all holds nothing; its journal may still hold the end."""
    ended, where, rounds, answered = None, "", 0, False
    try:
        # summed up as it is read, nothing of it kept (fold.Summed)
        log, summed = fold_log(path, None, Summed) if path.is_file() else (None, None)
    except (InputError, OSError):
        log = None
    if log is not None:
        if summed.game_end is not None:
            ended, where = summed.game_end, "the file"
        rounds = len(summed.fold.whole_rounds())
        answered = summed.answered
    if ended is None or not answered:  # the answers come after the game's end: the journal may hold them alone
        # (the file's own metadata tells its journal from another recording's: a recovered copy keeps it)
        mine = log.metadata.get(RECORDER_METADATA, {}) if log is not None else {}
        for key, payload in _journal_events(wal_path(journal_of), session, ("SessionEnded", "QuestionnaireAnswered"),
                                            mine):
            if key == "QuestionnaireAnswered":
                answered = True
            elif ended is None and getattr(payload, "source", "") == "game":
                ended, where = payload, "its recorder's journal beside it"
    if ended is not None:
        rounds = int(ended.rounds_played)
    return CutEnd(ended, where, rounds, answered)


def _journal_events(journal: Path, session: str, tags: tuple[str, ...], metadata: dict[str, str]):
    """(tag, decoded event) of each record of `tags` in the recorder's journal `journal` of `session`, in order;
    none when there is no journal, it cannot be read, or it is of another session or of another recording than the
    one whose recorder metadata is `metadata` (wal.not_its)."""
    from pairplay.schemas.events import decode_event

    if not journal.is_file():
        return
    try:
        read = read_journal(journal)
    except (NotAJournal, OSError):
        return
    if read.session != session or not_its(read, metadata):
        return
    for key, payload, _ in read.records:
        tag = key.rsplit("/", 1)[-1]
        if tag in tags:
            try:
                yield tag, decode_event(payload)
            except Exception:  # (one that does not decode: recover records it; it ends nothing here)
                continue

"""The study journal: what the experimenter did, one JSON object a line (journal.jsonl).

Rule: the games themselves are recorded by the bus recorder (one MCAP file per
game); the journal records the study around them: who was registered (a
pseudonymous id, never a name) and their consent (ConsentGiven), which game of which phase a session was, how it
ended, what the experimenter paused, aborted or marked invalid and why, the
bias policies combined, where a participant's data was exported or copied by a verb (CopyWritten), the
participants deleted. A study's state is the fold
of its journal (replay/studydata.py). Each line is a tagged Struct (field
"event"), readable by any JSON tool; unknown fields are ignored on read, so
an older pairplay reads a newer journal's lines of the types it knows; a type
it does not know (PolicyBuilt, to a pairplay older than it) is refused in one
line naming the journal's line, never skipped.

One exception to append-only, by design: deleting a participant (the right to
erasure) rewrites the journal without that participant's lines and appends a
ParticipantDeleted that holds no id, only counts and the merged policies
that had used their data.
"""

from __future__ import annotations

import msgspec
from .nesting import JsonDecoder
from .repeated import refuse_repeated


class JournalEvent(msgspec.Struct, frozen=True, kw_only=True, tag_field="event"):
    time_ns: int = 0
    by: str = "experimenter"


class StudyCreated(JournalEvent, tag="StudyCreated"):
    study: str
    study_file_sha256: str
    software_version: str = ""


class ParticipantRegistered(JournalEvent, tag="ParticipantRegistered"):
    participant: str  # pseudonymous id, e.g. p01
    joins: str  # the phase they first play


class ConsentGiven(JournalEvent, tag="ConsentGiven"):
    """A person's informed consent, recorded by the experimenter who holds their signed form: the form's version
    (the study's consent form then, or the one `--form` named; "" if it names none) and, in `time_ns`, when it was
    recorded. A person's game is refused without one to the study's form of now (services/protocol.py); a persona
    playing in a rehearsal needs none."""

    participant: str
    form: str = ""
    # when the person signed, when it was before it was recorded (a consent held on paper, `--given-at`);
    # 0: given when recorded (time_ns). Both are kept: an audit reads when it was given and when journaled
    given_ns: int = 0


class ConsentFormChanged(JournalEvent, tag="ConsentFormChanged"):
    """The study's consent form from now on (an ethics amendment: `protocol consent-form`), instead of the study
    file's `consent_form`, which is fixed with the folder. A person whose consent is to an earlier form plays
    only once their consent to this one is recorded."""

    form: str


class GameStarted(JournalEvent, tag="GameStarted"):
    participant: str
    phase: str
    game: int  # within the phase
    session: str
    recording: str  # path relative to the study folder
    bias: str = ""  # the merged policy file a pi-reuse game starts from
    # the core persona that played instead of a person (a dress rehearsal: `protocol pilot`, `serve --pilot`);
    # "" for a person (and every game of a journal older than the field)
    scripted: str = ""


class GamePaused(JournalEvent, tag="GamePaused"):
    session: str
    participant: str


class GameResumed(JournalEvent, tag="GameResumed"):
    session: str
    participant: str


class GameEnded(JournalEvent, tag="GameEnded"):
    session: str
    participant: str
    outcome: str  # "completed" | "aborted"
    reason: str = ""
    rounds_played: int = 0
    policy: str = ""  # the rebuilt policy file, relative to the study folder
    questionnaire: bool = False  # answers recorded in the game's recording


class PolicyBuilt(JournalEvent, kw_only=True, tag="PolicyBuilt"):
    """The policy of a completed game, built from its recording after the game was journaled without one
    (a signal stopped the server during the game's questionnaire: no time to read the recording back)."""

    session: str
    participant: str
    policy: str  # the rebuilt policy file, relative to the study folder
    by: str = "pairplay"


class SessionMarkedInvalid(JournalEvent, tag="SessionMarkedInvalid"):
    session: str
    participant: str
    reason: str


class BiasCombined(JournalEvent, tag="BiasCombined"):
    """The phase's bias policy: the combiner's answer (algorithm 4) and each user's profile (algorithm 3)."""

    phase: str  # the phase that reuses it
    from_phase: str
    request_id: str
    inputs: list[str]  # policy files, relative to the study folder
    users: list[str]
    output: str  # the merged policy file
    actions: list[int]
    decided_by: list[str]
    profiles: dict[str, dict[str, float]] = {}  # user -> speech, head (shares), facial, gaze (0/1), compared_states
    # why the profiles and the merged policy are partial ("" if not): core/policies.py partial_inputs, as the
    # combiner's merged file says it and `pairplay profile` says "PARTIAL profile: ..." (they said nothing here)
    partial: str = ""


class ParticipantExported(JournalEvent, tag="ParticipantExported"):
    """A participant's data was exported to a zip: where (absolute), so that their deletion can name the copy
    it cannot reach (one outside the study folder; inside it an export goes only to exports/<id>.zip)."""

    participant: str
    path: str
    sha256: str = ""


class CopyWritten(JournalEvent, kw_only=True, tag="CopyWritten"):
    """A file derived from participants' data (a recording, a game's or a bias policy, the study folder) that a
    verb wrote where their deletion would not erase it by itself (`rebuild --out`, `view --out`, `counterfactual`,
    `report --out`, `recover -o`, `combine -o`: replay/copies.py): whose data it holds, which verb wrote it,
    where (absolute) and the SHA-256 of the bytes written, so that the deletion erases it while it is still
    pairplay's unchanged file and names it otherwise."""

    participants: list[str]
    verb: str
    path: str
    sha256: str
    by: str = "pairplay"


class FlawKept(msgspec.Struct, frozen=True, kw_only=True):
    """A bias policy made with a game of the deleted participant that was marked invalid since: the flaw is a fact
    about the merged file, not the person, so the deletion keeps it without their id (replay/biases.py reads it:
    status, sessions.csv and the report went on flagging nothing, and the plan played new games on the file)."""

    merged: str  # the bias policy (a BiasCombined output)
    # not the mark's reason (the experimenter's words about the deleted person's game: replay/biases.py):
    # "reason withheld: its participant was deleted" (an older pairplay kept the reason, the id redacted)
    reason: str
    marked_ns: int = 0  # when the game was marked invalid


class ParticipantDeleted(JournalEvent, tag="ParticipantDeleted"):
    """A participant was erased; no id is kept, only what the deletion touched."""

    deletion: str  # a random id of this deletion
    sessions_removed: int
    files_removed: int
    journal_lines_removed: int
    merged_policies_using_them: list[str] = []
    key_file_line_removed: bool = False
    copies_erased: int = 0  # journaled copies outside the folder's own places, erased as pairplay's unchanged files
    # the person withdrew their consent (`participant delete --consent-withdrawn`): their ConsentGiven went with
    # their other lines; this anonymous line keeps that it was withdrawn, and when
    consent_withdrawn: bool = False
    flaws_kept: list[FlawKept] = []  # the bias policies made with their games marked invalid since (FlawKept)


JOURNAL_TYPES = (StudyCreated, ParticipantRegistered, ConsentGiven, ConsentFormChanged, GameStarted, GamePaused,
                 GameResumed, GameEnded, PolicyBuilt, SessionMarkedInvalid, BiasCombined, ParticipantExported, CopyWritten, ParticipantDeleted)
AnyJournal = JOURNAL_TYPES[0]
for _t in JOURNAL_TYPES[1:]:
    AnyJournal = AnyJournal | _t  # type: ignore[assignment]

_decoder = JsonDecoder(AnyJournal)
_encoder = msgspec.json.Encoder()


def decode_line(line: bytes | str) -> JournalEvent:
    """The event of one journal line; msgspec.ValidationError for a key given twice (`repeated`: msgspec keeps
    the last, so a second "participant" moved a line to another participant), DecodeError for what is no event."""
    refuse_repeated(line)
    return _decoder.decode(line)


def encode_line(event: JournalEvent) -> bytes:
    return _encoder.encode(event) + b"\n"

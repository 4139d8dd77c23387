"""A study's bias policies as its journal holds them: every combination kept, a phase's last one current.

Rule: each combination (journal BiasCombined) writes a file of its own and none is ever replaced: the first
of a phase is `merged/<phase>-bias.policy.json`, a later one `merged/<phase>-bias-v<n>.policy.json`
(`next_output`), so the file a game was played on (its GameStarted `bias`) stays for the record. A
combination is *flawed* when a game whose policy it took was marked invalid after it (`invalid_inputs`: it
never takes one marked before). The plan (replay/studydata.py StudyData.plan) then counts the combination
as not done: it asks for the invalid game again, then for the combination again, and no game starts on a
flawed bias policy meanwhile. The games already played on it stay valid (`played_on`): their people played
them honestly, on the bias policy the study had then, and a second game of the same phase would find them
returning users, which the design does not have; the report names the bias policy each game used and flags
a flawed one, and the experimenter who wants them played again marks them invalid too (then the plan asks
for them, on the new bias policy). A flaw is a fact about the merged file, not about the person: a
participant's deletion removes their games and marks, and keeps each flaw they made without their id
(`flaws_of`, journal ParticipantDeleted `flaws_kept`), which `invalid_inputs` counts as "a game of a deleted
participant" (it was forgotten: the plan played new games on the flawed file, and nothing flagged the games played
on it). The flaw kept is which bias policy, that a game it took was marked invalid, and when; never the mark's
free-text reason, which is the experimenter's words about that person's game (a name, a health note, why they
left: trial33 C kept "(Anna Schmidt) told us she has epilepsy" in the journal, status, sessions.csv and the report
after a withdrawal of consent): it is WITHHELD, in what the deletion writes and in how a kept flaw is read (an older
pairplay's deletion wrote the reason). All of it is a fold of the journal: nothing here writes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pairplay.numbers import agreement, counted
from pairplay.schemas import journal as j

if TYPE_CHECKING:
    from .studydata import Game, StudyState


def versions(state: "StudyState", phase: str) -> list[j.BiasCombined]:
    """Every combination of `phase`'s bias policy, in the journal's order (the last one is current)."""
    return [c for c in state.combinations if c.phase == phase]


def next_output(state: "StudyState", phase: str) -> str:
    """The file the next combination of `phase` writes: a new one for each (module rule)."""
    n = len(versions(state, phase)) + 1
    return f"merged/{phase}-bias.policy.json" if n == 1 else f"merged/{phase}-bias-v{n}.policy.json"


def _by_policy(state: "StudyState") -> dict[str, "Game"]:
    return {g.ended.policy: g for g in state.games.values() if g.ended is not None and g.ended.policy}


DELETED_GAME = "a game of a deleted participant"  # a flaw kept by a deletion names no one
WITHHELD = "reason withheld: its participant was deleted"  # what a kept flaw says in place of the mark's reason


def invalid_inputs(state: "StudyState", c: j.BiasCombined) -> list[tuple[str, str]]:
    """(game, reason) of each game marked invalid whose policy combination `c` took (none: it is sound); a
    deleted participant's game as DELETED_GAME, from the flaws their deletion kept."""
    by_policy = _by_policy(state)
    bad = [by_policy[p] for p in c.inputs if p in by_policy and by_policy[p].invalid]
    # a kept flaw's own reason is never shown: an older pairplay's deletion kept the mark's words (module rule)
    return [(g.session, g.invalid) for g in bad] + [(DELETED_GAME, WITHHELD) for k in state.flaws_kept
                                                     if k.merged == c.output]


def flaws_of(state: "StudyState", pid: str) -> list[j.FlawKept]:
    """The flaws participant `pid`'s games marked invalid made in the combinations that took them, as their
    deletion keeps them: the bias policy and the mark's time, the reason WITHHELD (module rule)."""
    by_policy = _by_policy(state)
    return [j.FlawKept(merged=c.output, reason=WITHHELD, marked_ns=g.invalid_ns)
            for c in state.combinations for p in c.inputs
            if (g := by_policy.get(p)) is not None and g.invalid and g.participant == pid]


def flawed(state: "StudyState", phase: str) -> j.BiasCombined | None:
    """`phase`'s current combination if it is flawed, else None."""
    c = state.combined.get(phase)
    return c if c is not None and invalid_inputs(state, c) else None


def played_on(state: "StudyState", c: j.BiasCombined) -> list["Game"]:
    """The games started on combination `c`'s bias policy (their GameStarted `bias`)."""
    return [g for g in state.games.values() if g.bias and g.bias == c.output]


def flaw_words(state: "StudyState", c: j.BiasCombined) -> str:
    """"made with <session> (marked invalid since: <reason>), ..." of each; "" if `c` is sound."""
    bad = invalid_inputs(state, c)
    return "made with " + ", ".join(f"{who} (marked invalid since: {why})" for who, why in bad) if bad else ""


def replaced_by(state: "StudyState", c: j.BiasCombined) -> j.BiasCombined | None:
    """The combination of the same phase that came after `c` (None: `c` is current)."""
    later = versions(state, c.phase)
    at = next(i for i, v in enumerate(later) if v is c or v == c)
    return later[at + 1] if at + 1 < len(later) else None


def combined_words(state: "StudyState", c: j.BiasCombined) -> str:
    """"combined into <file>", and, for one made again, the file it takes the place of and why (the pilot's step
    line, the console's answer)."""
    earlier = versions(state, c.phase)
    at = next((i for i, v in enumerate(earlier) if v == c), 0)
    before = earlier[at - 1] if at > 0 else None
    return f"combined into {c.output}" + (
        f" (in place of {before.output}, {flaw_words(state, before) or 'an earlier combination'}; kept for the "
        "record)" if before is not None else "")


def _sessions(games: list["Game"]) -> str:
    return ", ".join(g.session for g in games)


def marked_note(state: "StudyState", session: str) -> str:
    """What marking game `session` invalid did to the bias policies (the words after `protocol mark-invalid`'s
    "marked invalid: <reason>", and the console's answer): each current bias policy combined from it, what the
    plan asks now, and the games played on it and what becomes of them; "" if no current combination took it."""
    game = state.games.get(session)
    policy = game.ended.policy if game is not None and game.ended is not None else ""
    said = []
    for c in state.combined.values():
        if not policy or policy not in c.inputs:
            continue
        on = [g for g in played_on(state, c) if not g.invalid]  # one marked already is played again anyway
        said.append(f"the bias policy of {c.phase} ({c.output}) was combined from it: the plan asks for the game "
                    f"again, then the combination again, into a new file (this one kept for the record)"
                    + (f"; {counted(len(on), 'game')} played on it ({_sessions(on)}) "
                       f"{agreement(len(on), 'stays', 'stay')} valid, played honestly on the bias policy of their "
                       f"time (the report names it and flags it): mark {agreement(len(on), 'it', 'them')} invalid "
                       f"too to have {agreement(len(on), 'it', 'them')} played again on the new one" if on
                       else "; no game was played on it"))
    return "; ".join(said)


def step_note(state: "StudyState", phase: str) -> str:
    """The plan's note on `phase`'s combine step when its current bias policy is flawed ("" otherwise)."""
    c = flawed(state, phase)
    if c is None:
        return ""
    return f"{c.output} was {flaw_words(state, c)}: this step makes a new bias policy, that file kept for the record"


def bias_of(state: "StudyState", g: "Game") -> j.BiasCombined | None:
    """The combination whose bias policy game `g` was played on (None: it was played on none)."""
    return next((c for c in state.combinations if g.bias and c.output == g.bias), None)


def game_note(state: "StudyState", g: "Game") -> str:
    """The plan's note on a game played on a flawed bias policy ("" otherwise): it stays valid (module rule)."""
    c = bias_of(state, g)
    if c is None or not invalid_inputs(state, c):
        return ""
    return (f"played on {c.output}, {flaw_words(state, c)}: it stays valid, played honestly on it; mark it invalid "
            "to play it again on the new one")

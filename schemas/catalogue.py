"""The event catalogue as data: who publishes each event and what it means.

Rule: every event type in `events.EVENT_TYPES` has one row here; the README's
catalogue is generated from these rows and the Structs' own fields
(`python -m pairplay.schemas.catalogue --write README.md`, which also redraws
the event flow of docs/architecture.md from FLOW), and a test keeps them in step.
"""

from __future__ import annotations

import msgspec

from .envelope import Event, tag_of
from .events import EVENT_TYPES

# tag -> (published by, meaning)
CATALOGUE: dict[str, tuple[str, str]] = {
    "ServiceStarted": ("any service", "a service is up; `resumed_events` > 0 when it rebuilt its state from the log; `marks`: the inputs it marks where it took them (the game: pause and resume, ControlTaken)"),
    "SessionStarted": ("game", "the session's full config: participant, seed, rounds, learner, observed-card source, version"),
    "RoundStarted": ("game", "a new deal: the face of each of the 18 cards (the outcome of the deal stream)"),
    "CardPicked": ("participant / board", "an input: a card was touched; the game may reject it"),
    "CardRevealed": ("game", "the game accepted a pick and turned the card face up"),
    "PickRejected": ("game", "an illegal pick (off the board, face up, matched, third card), with the reason"),
    "CardObserved": ("participant (intended) / game (first pick, gaze)", "the card the user looks at before the second pick"),
    "SuggestionRequested": ("game", "the state (thesis 4.1), observed and matching card, covered cards: the learner must act"),
    "SuggestionMade": ("learner", "the composite action (0..87), how it was chosen, epsilon/alpha/psi, its target card"),
    "RobotActed": ("robot", "what the robot bridge sent to which backend, and the robot's acknowledgement or failure"),
    "SuggestionPerceived": ("participant (simulated)", "what the simulated user made of it: considered, consistent, candidate set"),
    "WrongSuggestionPressed": ("board (human study)", "the participant pressed the wrong-suggestion button: -3 and a new suggestion"),
    "TurnResolved": ("game", "the two cards of a turn, match or miss, the time between the picks"),
    "RewardGiven": ("learner", "the reward of a suggestion and whether it was learned from (ignored: no update)"),
    "QUpdated": ("learner", "one Q-learning update (eq. 5.2): state, action, alpha, reward, Q before and after"),
    "LSPIUpdated": ("learner", "one sample learned by online LSPI (algorithm 2): state, action, reward, samples so far, whether the policy was improved, Q before and after, a digest of the weights"),
    "RoundEnded": ("game", "the board is clear: turns and matches of the round"),
    "CombineRequested": ("experimenter / any client", "profile and merge these policies or recordings (algorithms 3, 4)"),
    "PolicyCombined": ("combiner", "the merged policy, the rule that decided each state, the merged user information"),
    "QuestionnaireAnswered": ("board / experimenter", "a participant's answers to a questionnaire (thesis 7.2)"),
    "SessionPaused": ("experimenter", "the console paused the game: the game refuses touches until it resumes"),
    "SessionResumed": ("experimenter", "the console resumed a paused game"),
    "ControlTaken": ("game", "the game took a pause or resume here, among its outputs (the console's message it took: its tag, source and seq): verify feeds it where the game took it, not where the recorder filed it"),
    "SessionAborted": ("experimenter", "the console stopped the game, with the reason: the game ends the session"),
    "GazeFixated": ("tracker (eye tracker)", "the participant fixated a card: the observed card of a 'gaze' session"),
    "MessageRejected": ("any service", "a bus message a service refused (malformed, unknown tag, wrong session, out of order), with the reason"),
    "SessionEnded": ("game", "the session is over: why (completed, interrupted by a signal, aborted by the experimenter, a service failed) and how far it got"),
    "RecordingGap": ("recorder", "a restarted recorder continues the session's file: events copied, refilled from the services, the gap's bounds"),
}

# tag -> (publishing services, consuming services), as the services' code reads them; the
# recorder, the view and the lab's board (which draws its pages from the log) subscribe to
# every event (`pairplay/<session>/**`) and are not listed as consumers.
# docs/architecture.md draws this table (mermaid()); a test keeps both in step with CATALOGUE.
FLOW: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "ServiceStarted": (("any service",), ()),
    "SessionStarted": (("game",), ("learner", "participant")),
    "RoundStarted": (("game",), ("participant",)),
    "CardPicked": (("participant", "board"), ("game",)),
    "CardRevealed": (("game",), ("participant",)),
    "PickRejected": (("game",), ("participant",)),
    "CardObserved": (("participant",), ("game",)),
    "GazeFixated": (("tracker",), ("game",)),
    "SuggestionRequested": (("game",), ("learner",)),
    "SuggestionMade": (("learner",), ("participant", "robot")),
    "RobotActed": (("robot",), ()),
    "SuggestionPerceived": (("participant",), ("learner",)),
    "WrongSuggestionPressed": (("board",), ("game",)),
    "TurnResolved": (("game",), ("learner", "participant")),
    "RewardGiven": (("learner",), ()),
    "QUpdated": (("learner",), ()),
    "LSPIUpdated": (("learner",), ()),
    "RoundEnded": (("game",), ()),
    "CombineRequested": (("experimenter",), ("combiner",)),
    "PolicyCombined": (("combiner",), ("experimenter",)),
    "QuestionnaireAnswered": (("board",), ()),
    "SessionPaused": (("experimenter",), ("game",)),
    "SessionResumed": (("experimenter",), ("game",)),
    "SessionAborted": (("experimenter",), ("game",)),
    "ControlTaken": (("game",), ()),
    "MessageRejected": (("any service",), ()),
    "SessionEnded": (("game",), ("learner", "participant", "robot")),
    "RecordingGap": (("recorder",), ()),
}

_ENVELOPE = {f.name for f in msgspec.structs.fields(Event)}


def rows() -> list[tuple[str, str, str, str]]:
    out = []
    for t in EVENT_TYPES:
        tag = tag_of(t)
        publisher, meaning = CATALOGUE[tag]
        fields = ", ".join(f.name for f in msgspec.structs.fields(t) if f.name not in _ENVELOPE)
        out.append((tag, publisher, meaning, fields))
    return out


def markdown() -> str:
    lines = ["| event | published by | meaning | fields (besides the envelope) |", "|---|---|---|---|"]
    lines += [f"| `{tag}` | {pub} | {meaning} | {fields} |" for tag, pub, meaning, fields in rows()]
    return "\n".join(lines)


def mermaid() -> str:
    """The event flow as a Mermaid flowchart: one edge per (publisher, event, consumer) of FLOW;
    an event nobody but the recorder consumes goes to the node `log`."""
    def node(name: str) -> str:
        return name.replace(" ", "_")
    lines = ["flowchart LR"]
    for tag, (publishers, consumers) in FLOW.items():
        for pub in publishers:
            for con in consumers or ("log",):
                lines.append(f"    {node(pub)} -- {tag} --> {node(con)}")
    lines.append('    log[("recorder (every event to MCAP) and view")]')
    return "\n".join(lines)


START, END = "<!-- catalogue:start -->", "<!-- catalogue:end -->"
FLOW_START, FLOW_END = "<!-- flow:start -->", "<!-- flow:end -->"


def inject(text: str) -> str:
    """`text` (the README) with the catalogue between its markers replaced."""
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}\n{markdown()}\n{END}{tail}"


def inject_flow(text: str) -> str:
    """`text` (docs/architecture.md) with the Mermaid diagram between its markers replaced."""
    head, rest = text.split(FLOW_START, 1)
    _, tail = rest.split(FLOW_END, 1)
    return f"{head}{FLOW_START}\n```mermaid\n{mermaid()}\n```\n{FLOW_END}{tail}"


if __name__ == "__main__":
    import sys
    from pathlib import Path

    if sys.argv[1:2] == ["--write"]:
        path = Path(sys.argv[2] if len(sys.argv) > 2 else "README.md")
        path.write_text(inject(path.read_text()))
        arch = path.parent / "docs" / "architecture.md"
        if arch.exists():
            arch.write_text(inject_flow(arch.read_text()))
    else:
        print(markdown())

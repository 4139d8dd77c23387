"""How fast the view draws, beside its raw references (rows for `pairplay bench`).

Rule: each row measures the view and its reference in the same run, on the
same events. The live row's events are a scripted session (`scripted_events`): rounds
played by the board rules (core.board) with seeded random picks and
suggestions, every event type a session publishes, in a session's order, with
envelope times 3 ms apart, and the Q-table updated by the thesis's rule
Q += alpha (r - Q) (section 5.1). It exercises the view exactly like a session;
it is not a model of a user.

Rows:
- view from a recording: events/s of `pairplay view --recording` (read, decode,
  fold, draw into an .rrd) on a real simulated session recorded by `pairplay
  session`'s runner, reference = reading and decoding the same recording alone.
  Goal: >= 1,000 events/s with the Q-table rate-limited.
- live session with the view attached: events/s a BLOCK publisher reaches on
  the bus while the view subscribes and draws, reference = the same publisher
  with a bare counting subscriber. Goal: ratio >= 0.8 (the view's Zenoh
  receive path only queues, its drawing coalesces and its drawing thread runs
  at a lower priority, so it must not hold the session back). A context row
  gives the view with `--nice 0` in the same runs (coalescing alone).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterator


import numpy as np
import rerun as rr

from pairplay.core.board import Board
from pairplay.core.geometry import N_CARDS, N_STATES, state_of
from pairplay.core.actions import N_ACTIONS
from pairplay.replay.reader import read_log
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas import events as ev
from pairplay.schemas.events import encode_event
from pairplay.schemas.envelope import stamped, tag_of
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig

SOURCES = {  # who publishes what (schemas/events.py)
    "SessionStarted": "game", "RoundStarted": "game", "CardRevealed": "game", "CardObserved": "participant",
    "SuggestionRequested": "game", "SuggestionMade": "learner", "SuggestionPerceived": "participant",
    "TurnResolved": "game", "RewardGiven": "learner", "QUpdated": "learner", "RoundEnded": "game",
    "SessionEnded": "game", "CardPicked": "participant",
}


def scripted_events(rounds: int = 3, seed: int = 0, session: str = "bench", t0_ns: int = 1_700_000_000_000_000_000,
                    step_ns: int = 3_000_000) -> tuple[list, np.ndarray]:
    """A scripted session's stamped events and the Q-table they leave (see the module rule)."""
    rng = np.random.default_rng(seed)
    out: list = []
    seqs: dict[str, int] = {}

    def emit(event) -> None:
        source = SOURCES[tag_of(type(event))]
        seqs[source] = seqs.get(source, 0) + 1
        out.append(stamped(event, session=session, source=source, seq=seqs[source], time_ns=t0_ns + len(out) * step_ns))

    q = np.zeros((N_STATES, N_ACTIONS))
    emit(ev.SessionStarted(config=SessionConfig(session=session, participant="sim:scripted", persona="scripted",
                                                seed=seed, rounds=rounds)))
    for r in range(rounds):
        faces = [int(f) for f in rng.permutation(np.arange(N_CARDS) // 2)]
        board = Board.from_faces(faces)
        emit(ev.RoundStarted(round=r, faces=faces))
        turn = 0
        while not board.round_over:
            first, second = _turn(emit, rng, q, board, faces, r, turn)
            board, _ = board.pick(first)
            board, _ = board.pick(second)
            board, _ = board.resolve()
            turn += 1
        emit(ev.RoundEnded(round=r, turns=turn, matches=N_CARDS // 2))
    emit(ev.SessionEnded(rounds_played=rounds))
    return out, q


def _turn(emit, rng, q, board: Board, faces, r: int, turn: int) -> tuple[int, int]:
    """The 11 events of one turn (first pick, suggestion, second pick, reward, update)."""
    covered = [c for c in range(N_CARDS) if board.covered >> c & 1]
    first = int(rng.choice(covered))
    match = board.partner(first)
    rest = board.covered & ~(1 << first)
    observed = match if rng.random() < 0.5 else int(rng.choice([c for c in range(N_CARDS) if rest >> c & 1]))
    state = state_of(observed, match, rest)
    act = int(rng.integers(N_ACTIONS))
    matched = observed == match
    reward = (1.0 if matched else -1.0) + (1.0 / 3 if rng.random() < 0.5 else 0.0)
    before = float(q[state, act])
    q[state, act] = before + 0.5 * (reward - before)
    emit(ev.CardPicked(round=r, turn=turn, card=first))
    emit(ev.CardRevealed(round=r, turn=turn, card=first, face=faces[first], pick=0))
    emit(ev.CardObserved(round=r, turn=turn, card=observed, observed_source="intended"))
    emit(ev.SuggestionRequested(round=r, turn=turn, attempt=0, state=state, observed=observed, match=match,
                                covered_mask=rest, first=first))
    emit(ev.SuggestionMade(round=r, turn=turn, attempt=0, state=state, action=act, chosen_by="explore",
                           epsilon=0.9, alpha=0.5, psi=0.0, observed=observed, target=match))
    emit(ev.SuggestionPerceived(round=r, turn=turn, attempt=0, considered=True, consistent=True, candidate_size=3,
                                second=observed))
    emit(ev.CardPicked(round=r, turn=turn, card=observed))
    emit(ev.CardRevealed(round=r, turn=turn, card=observed, face=faces[observed], pick=1))
    emit(ev.TurnResolved(round=r, turn=turn, first=first, second=observed, matched=matched,
                         round_over=matched and bin(board.matched).count("1") == N_CARDS - 2))
    emit(ev.RewardGiven(round=r, turn=turn, attempt=0, state=state, action=act, reward=reward, learned=True))
    emit(ev.QUpdated(round=r, turn=turn, attempt=0, state=state, action=act, alpha=0.5, reward=reward,
                     q_before=before, q_after=float(q[state, act])))
    return first, observed


def write_recording(events: list, path: Path) -> Path:
    """The events as a pairplay MCAP recording (replay's writer, one channel per key)."""
    writer = EventLogWriter(path)
    encode = encode_event
    for e in events:
        writer.write(event_key(e.session, e.source, tag_of(type(e))), encode(e), log_time_ns=e.time_ns)
    writer.close()
    return path


def _row(row, value, unit, reference, reference_value, goal) -> dict:
    return {"row": row, "value": round(value, 1), "unit": unit, "reference": reference,
            "reference_value": round(reference_value, 1),
            "ratio": round(value / reference_value, 3) if reference_value else None, "goal": goal}


def real_recording(path: Path, rounds: int = 60) -> Path:
    """A simulated session recorded by `pairplay session`'s own runner (tatiana: she considers
    most suggestions, so the Q-table keeps changing)."""
    from pairplay.services.session import run_session

    config = SessionConfig(session="bench-rec", participant="sim:tatiana", persona="tatiana", seed=1, rounds=rounds)
    return run_session(config, path)


def bench_view_from_recording(rounds: int = 60) -> dict:
    from pairplay.services.view.drive import drive
    from pairplay.services.view.rerun_logger import RerunView
    from pairplay.services.view.sources import recording_items

    with tempfile.TemporaryDirectory() as tmp:
        mcap = real_recording(Path(tmp) / "bench.mcap", rounds)
        t = time.perf_counter()
        n_read = len(read_log(mcap).events)
        read_rate = n_read / (time.perf_counter() - t)
        rec = rr.RecordingStream("pairplay-bench")
        rec.save(str(Path(tmp) / "bench.rrd"))
        t = time.perf_counter()
        summary = drive(RerunView(rec), recording_items(mcap))
        rec.flush()
        view_rate = summary.events / (time.perf_counter() - t)
        rec.disconnect()
    return _row(f"view a {rounds}-round session recording ({summary.events} events, Q-table logged "
                f"{summary.q_logged}x)", view_rate, "events/s", "read + decode the recording alone", read_rate,
                "view_recording")


def _publish_rate(bus, payloads: list[tuple[str, bytes]]) -> float:
    t = time.perf_counter()
    for key, payload in payloads:
        bus.put(key, payload)
    return len(payloads) / (time.perf_counter() - t)


_BARE_SUBSCRIBER = """
import sys, threading
from pairplay.services.bus import BusOptions, open_bus
done, n, want = threading.Event(), [0], int(sys.argv[2])
def count(key, payload):
    n[0] += 1
    if n[0] >= want:
        done.set()
with open_bus(BusOptions(listen=[], connect=[sys.argv[1]])) as bus:
    bus.subscribe("pairplay/bench-live/**", count)
    done.wait(60)
"""


def _publish_to(bus, payloads, command: list[str]) -> float:
    """Publish rate while `command` (a subscriber process) is attached; waits for it to match first."""
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while not bus.matching(payloads[0][0]):
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError(f"subscriber {command[:3]} never matched the publisher")
            time.sleep(0.05)
        return _publish_rate(bus, payloads)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def bench_live_not_slowed(rounds: int = 300, repeats: int = 3) -> list[dict]:
    """The view and the reference subscriber run as their own processes, as in a study;
    medians of `repeats` alternating runs (the machine is noisy). A context row: the view with
    `--nice 0` (coalesced drawing alone, its thread at the session's priority), same runs."""
    from pairplay.services.bus import open_bus

    events, _ = scripted_events(rounds, session="bench-live")
    encode = encode_event
    payloads = [(event_key(e.session, e.source, tag_of(type(e))), encode(e)) for e in events]
    bare, viewed, not_niced = [], [], []
    with open_bus() as session_bus, tempfile.TemporaryDirectory() as tmp:
        endpoint = session_bus.locators()[0]

        def view(i: int, *extra: str) -> list[str]:
            return [sys.executable, "-m", "pairplay", "view", "--session", "bench-live", "--connect", endpoint,
                    "--listen", "tcp/127.0.0.1:0", "--out", str(Path(tmp) / f"live{i}{len(extra)}.rrd"), *extra]

        for i in range(repeats):
            bare.append(_publish_to(session_bus, payloads,
                                    [sys.executable, "-c", _BARE_SUBSCRIBER, endpoint, str(len(payloads))]))
            viewed.append(_publish_to(session_bus, payloads, view(i)))
            not_niced.append(_publish_to(session_bus, payloads, view(i, "--nice", "0")))
    reference = "same publisher, bare counting subscriber process"
    return [_row(f"live session publishing {len(payloads)} events, view process attached", float(np.median(viewed)),
                 "events/s", reference, float(np.median(bare)), "view_live"),
            _row(f"live session publishing {len(payloads)} events, view process attached with --nice 0 "
                 "(coalesced drawing alone)", float(np.median(not_niced)), "events/s", reference,
                 float(np.median(bare)), None)]


def bench_rows(quick: bool = False) -> list[dict]:
    """`pairplay bench` rows of the view (about 9 s; `quick`: smaller runs, about 3 s)."""
    if quick:
        return [bench_view_from_recording(rounds=20), *bench_live_not_slowed(rounds=100, repeats=1)]
    return [bench_view_from_recording(), *bench_live_not_slowed()]


def events_iter(events: list) -> Iterator[tuple[object, None]]:
    """A list of events as a view source."""
    return ((e, None) for e in events)

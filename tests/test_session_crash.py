"""Crashes: a learner, participant or game killed mid-session resumes from the
log with no reward lost or counted twice, as if it had never crashed; a recorder killed with SIGKILL leaves a readable file
holding everything older than its flush interval, and `recover` completes it."""

import signal
import subprocess
import threading
from collections import Counter

import numpy as np
import pytest
from mcap.reader import make_reader

from pairplay.core.personas import persona
from pairplay.core.simulate import run_games
from pairplay.replay.fold import fold_events, stream_seed
from pairplay.replay.reader import read_log
from pairplay.replay.recover import recover
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import alive_key, event_key
from pairplay.schemas.config import DEFAULT_REWARD_BONUS
from pairplay.schemas.session import SessionConfig
from pairplay.services.runner import fetch_log
from pairplay.services.session import run_session
from pairplay.services.verify import verify_recording

from busutil import collect, listener, recorder_process, sigkill, wait_until
from cli_zygote import shared


def spawn(*args):
    """`pairplay run ARGS`, forked from this test process's zygote (tests/cli_zygote.py): SIGKILL and a restart,
    not its start-up, are what is tested (each `python -m pairplay` paid ~0.9 s of CPU importing)."""
    return shared().start(["run", *args], stderr=subprocess.STDOUT, text=False)


@pytest.mark.parametrize("victim", ["learner", "participant", "game"])
def test_a_killed_service_resumes_from_the_log_and_nothing_is_lost_or_doubled(tmp_path, victim):
    session_id = f"crash-{victim}"
    # 10 rounds (~140 turns of helmut's): the kill comes after 40 rewards (round 3-4), so most of the session is
    # played by the restarted service; 25 rounds proved no more for ~1.1 s more CPU a case
    config = SessionConfig(session=session_id, participant="sim:helmut", persona="helmut", seed=5, rounds=10,
                           reward_bonus=DEFAULT_REWARD_BONUS)
    ready, box = threading.Event(), {}

    def on_bus(bus):
        box["bus"], box["rewards"] = bus, collect(bus, f"pairplay/{session_id}/learner/RewardGiven")
        ready.set()

    session = threading.Thread(target=lambda: box.setdefault("path", run_session(
        config, tmp_path / f"{session_id}.mcap", external=(victim,), on_bus=on_bus, settle_timeout_s=60)))
    session.start()
    assert ready.wait(10)
    bus = box["bus"]
    endpoint = bus.locators()[0]
    join = ["--session", session_id, "--connect", endpoint]
    if victim == "game":  # the first game starts the session; the restarted one finds it in the log
        first = spawn("game", *join, "--participant", "sim:helmut", "--seed", "5", "--rounds", "10",
                      *[a for other in ("recorder", "learner", "participant") for a in ("--wait-for", other)])
    else:
        first = spawn(victim, *join)
    second = None
    try:
        assert wait_until(lambda: box["rewards"].qsize() >= 40, 60), first.stdout.read1().decode()
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        gone = alive_key(session_id, victim)
        assert wait_until(lambda: gone not in bus.alive_now(alive_key(session_id, "*")), 15)
        second = spawn(victim, *join)
        session.join(90)
        assert not session.is_alive()
        assert second.wait(30) == 0
    finally:
        for p in (first, second):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    log = read_log(box["path"])
    events = [r.event for r in log.events]
    made = [(e.round, e.turn, e.attempt) for e in events if isinstance(e, ev.SuggestionMade)]
    rewarded = [(e.round, e.turn, e.attempt) for e in events if isinstance(e, ev.RewardGiven)]
    assert Counter(rewarded) == Counter(made) and max(Counter(rewarded).values()) == 1  # none lost, none twice
    seqs = [e.seq for e in events if e.source == victim]
    assert seqs == sorted(set(seqs))  # the restarted service went on numbering where the log stopped
    starts = [e for e in events if isinstance(e, ev.ServiceStarted) and e.service == victim]
    assert len(starts) == 2 and starts[0].resumed_events == 0 and starts[1].resumed_events > 0
    fold = fold_events(events)
    study = run_games([persona("helmut")], [stream_seed(config)], config.rounds, reward_bonus=config.reward_bonus)
    assert fold.q_mismatches == 0 and np.array_equal(fold.q, study.q[0])  # as if it had never crashed
    assert [2 * t for t in fold.turns_per_round()] == list(study.picks[0])
    assert fold.ended is not None and verify_recording(box["path"]).ok


def test_a_recorder_killed_with_sigkill_keeps_all_but_its_last_flush_and_recovers(tmp_path):
    with listener() as bus, recorder_process(bus, "rk", tmp_path) as rec:
        key = event_key("rk", "participant", "CardPicked")
        assert wait_until(lambda: bus.matching(key))

        def burst(first, n):
            for seq in range(first, first + n):
                e = stamped(ev.CardPicked(round=0, turn=seq, card=seq % 18), session="rk",
                            source="participant", seq=seq, time_ns=seq)
                bus.put(key, encode_event(e))

        # its session's start first: a recording recover completes (one holding no session is refused by every verb)
        config = SessionConfig(session="rk", participant="sim:ashley", persona="ashley", seed=1, rounds=3)
        bus.put(event_key("rk", "game", "SessionStarted"),
                encode_event(stamped(ev.SessionStarted(config=config), session="rk", source="game", seq=1, time_ns=0)))
        burst(1, 3000)
        assert wait_until(lambda: len(fetch_log(bus, "rk")) == 3001)  # all 3000 (and the start) reached the recorder
        threading.Event().wait(0.3)  # quiet for longer than the 0.1 s flush interval
        burst(3001, 2000)
        sigkill(rec)
    path = tmp_path / "rk.mcap"
    log = read_log(path)
    assert log.truncated  # never finished: no summary, no footer
    seqs = [r.event.seq for r in log.events if r.event.source == "participant"]
    assert seqs[:3000] == list(range(1, 3001))  # nothing older than the last flush is lost
    assert seqs == list(range(1, len(seqs) + 1))  # what survived is a prefix, in order
    done = recover(path)
    with open(done.output, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == len(log.events)
    assert not read_log(done.output).truncated

"""A service that refuses the game's own SessionStarted or SessionEnded (task "refusal").

Before, the session watched only the recorder's refusal of the start: when the learner, the participant,
or a service in another process (`pairplay run learner`) refused the game's real start, the session waited
for it for ever (the learner never suggests) and never said why; when a service refused the game's real
end, the session waited for ever for that service to end. What must hold instead: the session stops within
seconds, its recording finished with the reason in it, ONE line naming the service and its reason, and a
refusal of a FORGED start (another seq) or a "contradicted:" notice does not stop it.
Real zenoh on loopback; the forger is a second bus session (a Zenoh client of the session's router).
"""

from __future__ import annotations

import subprocess
import threading
import time

import pytest

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.events import decode_event
from pairplay.schemas.keys import alive_key, event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.session import run_session

from busutil import wait_until
from cli_zygote import shared
from test_forge import forge, message

SETTLES_S = 30.0  # a session that stops at once is done in a few seconds even at load 30; before: never


def run_in_thread(config: SessionConfig, path, **kwargs) -> tuple[threading.Thread, dict]:
    """run_session in a daemon thread (a hung one must not hang the test run); `out`: its result or error."""
    out: dict = {}

    def run() -> None:
        try:
            out["path"] = run_session(config, path, **kwargs)
        except BaseException as err:  # judged by the test
            out["error"] = err
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, out


def finished(thread: threading.Thread, stop: threading.Event, timeout_s: float = SETTLES_S) -> bool:
    """Whether the session ended by itself within `timeout_s`; if not, it is stopped (so the test ends)."""
    thread.join(timeout_s)
    if thread.is_alive():
        stop.set()
        thread.join(10)
        return False
    return True


def test_a_policy_the_learner_cannot_take_is_refused_where_the_config_is_made():
    """SessionConfig checks policy_actions' length and codes where it is made (its __post_init__): the game never
    starts a session its learner would refuse (before: it published the start, and the learner refused it)."""
    with pytest.raises(ValueError, match="policy_actions must be 24 action codes 0..87, got 1 code"):
        SessionConfig(session="ref0", participant="sim:ashley", persona="ashley", seed=1, rounds=3,
                      algorithm="fixed", policy_actions=[0])
    with pytest.raises(ValueError, match="policy_actions must be 24 action codes"):
        SessionConfig(session="ref0", participant="sim:ashley", persona="ashley", seed=1, rounds=3,
                      algorithm="fixed", policy_actions=[88] * 24)


def test_a_learner_in_another_process_that_refuses_the_start_stops_the_session(tmp_path):
    """The session's --external learner refuses the game's real start (its refusal built by hand here: every
    config the game can start, the learner takes; what it refuses is a later pairplay's, or an earlier's)."""
    stop = threading.Event()
    buses: list[Bus] = []
    config = SessionConfig(session="ref2", participant="sim:ashley", persona="ashley", seed=1, rounds=3)
    thread, out = run_in_thread(config, tmp_path / "ref2.mcap", stop=stop, settle_timeout_s=5,
                                external=("learner",), on_bus=buses.append, bus_options=BusOptions(mode="router"))
    assert wait_until(lambda: buses and buses[0].locators(), 30)
    start_key = event_key("ref2", "game", "SessionStarted")
    with Bus(BusOptions(mode="client", connect=buses[0].locators())) as client:
        starts: list[bytes] = []
        client.subscribe(start_key, lambda _k, p: starts.append(p))
        assert wait_until(lambda: alive_key("ref2", "game") in client.alive_now(alive_key("ref2", "*")), 30)
        client.alive(alive_key("ref2", "learner"))  # the game waited for its learner: it starts now
        assert wait_until(lambda: starts, 30)
        seq = decode_event(starts[0]).seq
        client.put(*message("ref2", ev.MessageRejected(reason="cannot learn with this session config: by hand",
                                                       key=start_key, offending_source="game", offending_seq=seq),
                            1, source="learner"))
        assert finished(thread, stop, SETTLES_S + 30), "the session waited for a learner that had refused its start"
    err = out.get("error")
    assert err is not None and type(err).__name__ == "StartRefused", out
    line = err.line()
    assert line.startswith("the learner refused the session's start (cannot learn with this session config: by hand"), line
    assert str(tmp_path / "ref2.mcap") in line and "\n" not in line
    log = read_log(tmp_path / "ref2.mcap")
    assert not log.truncated and not log.bad
    events = [r.event for r in log.events]
    ends = [e for e in events if isinstance(e, ev.SessionEnded)]
    assert [e.reason for e in ends] == ["failed"] and "learner refused the session's start" in ends[0].detail
    assert any(isinstance(e, ev.MessageRejected) and e.source == "learner" and e.offending_seq == seq for e in events)


def test_a_refusal_of_a_forged_start_or_a_notice_does_not_stop_the_session(tmp_path):
    """Refusals naming the game's start key at another seq (what a guard says of a forged start), or a
    "contradicted:" notice of the real one's seq, are not refusals of the game's own start."""
    stop = threading.Event()
    buses: list[Bus] = []
    config = SessionConfig(session="ref3", participant="sim:ashley", persona="ashley", seed=1, rounds=3)
    started = threading.Event()

    def on_bus(bus: Bus) -> None:
        buses.append(bus)
        bus.subscribe(event_key("ref3", "game", "RoundStarted"), lambda _k, _p: started.set())
    thread, out = run_in_thread(config, tmp_path / "ref3.mcap", stop=stop, settle_timeout_s=5, on_bus=on_bus,
                                bus_options=BusOptions(mode="router"), external=("robot",))
    assert wait_until(lambda: buses and buses[0].locators(), 30)
    start_key = event_key("ref3", "game", "SessionStarted")
    with Bus(BusOptions(mode="client", connect=buses[0].locators())) as client:
        assert wait_until(lambda: alive_key("ref3", "game") in client.alive_now(alive_key("ref3", "*")), 30)
        for source, rejection in (
                ("learner", ev.MessageRejected(reason="a second SessionStarted in session ref3", key=start_key,
                                               offending_source="game", offending_seq=7)),
                ("participant", ev.MessageRejected(reason="contradicted: the SessionStarted taken as game's (seq 2) "
                                                   "was not game's", key=start_key, offending_source="game",
                                                   offending_seq=2))):
            client.put(*message("ref3", rejection, 1, source=source))
        time.sleep(0.5)
        client.alive(alive_key("ref3", "robot"))  # the game waited for a robot: it starts now
        assert started.wait(30)
        time.sleep(0.3)
        client.put(*message("ref3", ev.MessageRejected(reason="a second SessionStarted", key=start_key,
                                                       offending_source="game", offending_seq=9), 2,
                            source="learner"))
        assert finished(thread, stop, 60)
    assert "error" not in out, out
    ends = [r.event for r in read_log(tmp_path / "ref3.mcap").events if isinstance(r.event, ev.SessionEnded)]
    assert [e.reason for e in ends] == ["completed"]


def test_a_participant_that_refuses_the_games_real_end_does_not_keep_the_session_waiting(tmp_path):
    """A forged game event (not a start or an end: the forgery watch only names those) with a seq above the
    game's end makes every listener that gets the whole session (the participant, the recorder) refuse the
    game's real end as "not after the events game already published". Before: the session waited for ever
    for the participant to end."""
    stop = threading.Event()
    buses: list[Bus] = []
    config = SessionConfig(session="ref4", participant="sim:ashley", persona="ashley", seed=1, rounds=5)
    thread, out = run_in_thread(config, tmp_path / "ref4.mcap", stop=stop, settle_timeout_s=5,
                                on_bus=buses.append, bus_options=BusOptions(mode="router"), external=("robot",))
    assert wait_until(lambda: buses and buses[0].locators(), 30)
    with Bus(BusOptions(mode="client", connect=buses[0].locators())) as client:
        started = threading.Event()
        # the participant's first pick: it has taken the start (its messages come on subscriptions of their own
        # per origin, services/runner.py Node.subscribe, so the game's RoundStarted seen here does not tell)
        client.subscribe(event_key("ref4", "participant", "CardPicked"), lambda _k, _p: started.set())
        assert wait_until(lambda: alive_key("ref4", "game") in client.alive_now(alive_key("ref4", "*")), 30)
        client.alive(alive_key("ref4", "robot"))  # the game waited for a robot: it starts now
        assert started.wait(30)  # after the start: forged before it, it would make them refuse the start
        client.put(*forge("ref4", ev.RoundEnded(round=0, turns=1, matches=1), 5000))
        assert finished(thread, stop), "the session waited for a participant that had refused its end"
    err = out.get("error")
    assert err is not None and type(err).__name__ == "EndRefused", out
    line = err.line()
    assert "participant" in line and "refused the session's end" in line and "not after the events" in line, line
    log = read_log(tmp_path / "ref4.mcap")
    assert not log.truncated and not log.bad
    events = [r.event for r in log.events]
    assert any(isinstance(e, ev.MessageRejected) and e.source == "participant" and e.key.endswith("/SessionEnded")
               for e in events)


def test_a_game_run_alone_whose_start_a_service_refuses_ends_the_session_in_one_line(tmp_path):
    """`pairplay run game` of a person's session, and a simulated participant joining it (an operator's
    mix-up): the participant refuses the start ("not a simulated one"). Before: the game waited for ever
    for picks nobody would make; now it ends the session "failed", one line, exit 2."""
    from pairplay.services.participant import ParticipantLogic
    from pairplay.services.runner import Node

    game = shared().start(["run", "game", "--participant", "human:p1", "--session", "ref5", "--wait-for",
                           "participant"])  # its own process, forked (tests/cli_zygote.py): what it does, not its start
    stop = threading.Event()
    try:
        endpoint = game.stdout.readline().split()[1]
        with Bus(BusOptions(mode="client", connect=[endpoint])) as bus:
            ends = []
            bus.subscribe(event_key("ref5", "game", "SessionEnded"), lambda _k, p: ends.append(decode_event(p)))
            participant = Node(bus, ParticipantLogic(), "ref5", stop=stop)
            participant.start()
            participant.run_in_thread(stop)
            try:
                out, err = game.communicate(timeout=SETTLES_S)
            except subprocess.TimeoutExpired:
                pytest.fail("the game waited for ever for a participant that had refused its start")
            # the participant took the game's end: it ends too (before: it held the end behind the start)
            assert wait_until(lambda: not participant.thread.is_alive(), 10)
    finally:
        stop.set()
        if game.poll() is None:
            game.kill()
            game.wait()
    assert game.returncode == 2
    lines = [line for line in err.strip().splitlines() if not line.startswith(("INFO ", "WARNING "))]
    assert len(lines) == 1 and "the participant refused the session's start (participant 'human:p1' is not a " \
                               "simulated one)" in lines[0] and "session ref5" in lines[0], err[-2000:]
    assert [e.reason for e in ends] == ["failed"] and "participant refused" in ends[0].detail


FACES = [i // 2 for i in range(18)]


def test_on_a_recovering_bus_the_games_start_and_end_are_judged_by_seq_not_by_arrival(tmp_path):
    """Behind a `pairplay router` (`--recover`) every key has its own advanced publisher and cache, and
    what an outage held up comes back in order per key only (services/bus.py): the game's next event
    may arrive before its start, an earlier one after its end. The recorder and every service that gets
    the whole session judged a start or end by arrival there: they refused the game's real start as "not
    after the events game already published" (and the session then stopped: StartRefused) and noted its
    real end as "contradicted" (the recorder then waited for another end). On a recovering bus they judge
    by seq, as a service subscribed by tag does."""
    from pairplay.services.participant import ParticipantLogic
    from pairplay.services.recorder import Recorder
    from pairplay.services.runner import Node

    config = SessionConfig(session="ref6", participant="sim:ashley", persona="ashley", seed=1, rounds=1)
    start = message("ref6", ev.SessionStarted(config=config), 2)
    first_round = message("ref6", ev.RoundStarted(round=0, faces=FACES), 3)
    round_end = message("ref6", ev.RoundEnded(round=0, turns=9, matches=9), 9)
    end = message("ref6", ev.SessionEnded(reason="completed", rounds_played=1), 10)
    with Bus(BusOptions(recovery=True)) as bus:
        recorder = Recorder(bus, "ref6", tmp_path / "ref6.mcap")
        participant = Node(bus, ParticipantLogic(), "ref6")
        try:
            for n, (key, payload) in enumerate((first_round, start, end, round_end)):  # as an outage's recovery
                assert recorder.record(key, payload, n + 1), (key, recorder.refusals.total)
                out = participant.driver.receive(key, payload)
                assert not [e for e in out if isinstance(e, ev.MessageRejected)], out
                assert not recorder.guard.notices and not participant.driver.guard.notices
            assert recorder.ended and "SessionEnded" in recorder.guard.once
            assert participant.logic.users is not None  # it took the game's start
        finally:
            recorder.close()
    # a bus that keeps each publisher's order across keys (one link, no recovery) still judges by arrival
    with Bus(BusOptions()) as bus:
        recorder = Recorder(bus, "ref6", tmp_path / "ref6b.mcap")
        try:
            assert recorder.record(*first_round, 1)
            assert not recorder.record(*start, 2)  # a start behind the game's events there is not the game's
        finally:
            recorder.close()


@pytest.mark.parametrize("n", [1, 2, 7])
def test_a_count_of_refusals_reads_back_whatever_its_number(n):
    """The count's line says its noun ("1 message refused ...", numbers.counted), and the reader of counts
    (Refusals.counted: the console's and the report's totals) matched only "messages": a count of 1 was lost."""
    from collections import Counter

    from pairplay.services.guard import Refusals

    r = Refusals()
    r.shed(Counter({("board", "larger than 10 bytes"): n}))
    [count] = r.tick(10**9, force=True)
    assert Refusals.counted(count) == (("board", "shed unread (larger than N bytes)"), n), count.reason

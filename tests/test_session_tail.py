"""A session stopped after its deadline passed still records every event its own services published
(services/session.py `own_tail`, Recorder.close): an event the bus had not brought to the recorder, or that
still waited in the recorder's inbox, when a starved process's deadline ran out is this process's own work,
written at the close like the session's end. Before, only the end was: the events below it left a hole,
recorded as lost on the bus, and `rebuild` refused the session (CI: test_session_end[SIGINT] with the process
frozen right after its signal: "game seq 218 (1 event) lost")."""

import threading
import time

from busutil import wait_until

from pairplay.replay.reader import RECOVERED, read_log
from pairplay.replay.rebuild import rebuild_recording
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Deadline
from pairplay.services.recorder import Recorder
from pairplay.services.session import run_session


def _stopped_late(stop: threading.Event) -> None:
    stop.why, stop.deadline = "SIGINT", Deadline(0.0)  # its deadline ran out before the process ran on (a freeze)
    stop.set()


def _check(path, name):
    log = read_log(path)
    assert log.whole, log.error
    assert RECOVERED not in log.metadata, log.metadata.get(RECOVERED)  # no hole: nothing "lost on the bus"
    by_source: dict[str, list[int]] = {}
    for r in log.events:
        by_source.setdefault(r.event.source, []).append(r.event.seq)
    for source in ("game", "learner", "participant"):
        seqs = sorted(by_source[source])
        assert seqs == list(range(1, len(seqs) + 1)), (source, [s for s in range(1, seqs[-1]) if s not in seqs])
    counted = [(r.event.offending_source, r.event.reason) for r in log.events if isinstance(r.event, ev.MessageRejected)
               and r.event.offending_source in ("game", "learner", "participant")]
    # nothing the game published is counted as not received or still queued: it is written. The learner and the
    # participant may publish after the recorder took what they hold (their threads, which the passed deadline
    # did not wait for, work through their inboxes): those are counted, the last ones, never a hole
    # (a refusal of the participant's late pick, "the session is over; CardPicked ignored", is no loss)
    lost = [c for c in counted if "still queued" in c[1] or "not received" in c[1] or "lost" in c[1]]
    assert not [c for c in lost if c[0] == "game"], counted
    [end] = [r.event for r in log.events if isinstance(r.event, ev.SessionEnded)]
    assert (end.reason, end.detail) == ("interrupted", "SIGINT")
    assert rebuild_recording(path).partial.startswith(f"interrupted (SIGINT) after {end.rounds_played} of")


def test_events_the_bus_had_not_brought_when_the_deadline_passed_are_written(tmp_path, monkeypatch):
    """The game's last events were still on the bus (here: withheld from the recorder once the game has played
    on) when the stop came with its deadline passed."""
    config = SessionConfig(session="inflight", participant="sim:blind", persona="blind", seed=1, rounds=100000)
    stop, nodes, withheld = threading.Event(), {}, []
    enqueue = Recorder.enqueue

    def slow_bus(self, key, payload):  # (a Zenoh callback thread) what the bus has not brought yet
        if withheld or ("game" in nodes and nodes["game"].driver.seq > 200 and "/game/" in key):
            withheld.append(key)
            return None
        return enqueue(self, key, payload)
    monkeypatch.setattr(Recorder, "enqueue", slow_bus)

    def signal_later():
        wait_until(lambda: len(withheld) >= 5, 60)
        _stopped_late(stop)
    threading.Thread(target=signal_later, daemon=True).start()
    path = run_session(config, tmp_path / "inflight.mcap", stop=stop, nodes_out=nodes)
    assert len(withheld) >= 5
    _check(path, "inflight")


def test_events_still_in_the_recorders_inbox_when_the_deadline_passed_are_written(tmp_path, monkeypatch):
    """The recorder's thread had fallen behind (here: it takes nothing once the game has played on) and its
    inbox held the services' last events when the stop came with its deadline passed: the close sheds what
    waits, as a flood must not hold up the exit, but not this process's own events."""
    config = SessionConfig(session="queued", participant="sim:blind", persona="blind", seed=1, rounds=100000)
    stop, nodes, stalled = threading.Event(), {}, []
    step = Recorder.step

    def behind(self, timeout_s=0.05):  # on the recorder's thread
        if stalled or ("game" in nodes and nodes["game"].driver.seq > 200):
            stalled.append(1)
            time.sleep(0.005)
            return False
        return step(self, timeout_s)
    monkeypatch.setattr(Recorder, "step", behind)

    def signal_later():
        wait_until(lambda: stalled and nodes["game"].driver.seq > 230, 60)
        _stopped_late(stop)
    threading.Thread(target=signal_later, daemon=True).start()
    path = run_session(config, tmp_path / "queued.mcap", stop=stop, nodes_out=nodes)
    _check(path, "queued")

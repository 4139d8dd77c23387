"""`pairplay replay` paces a recording by its log times divided by the speed,
or not at all at `max`, and can move it to another session id."""

from pairplay.replay.reader import RecordedEvent
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import decode_event, encode_event
from pairplay.services.replayer import republish


class FakeBus:
    def __init__(self):
        self.sent = []

    def put(self, key, payload):
        self.sent.append((key, payload))


class FakeTime:
    def __init__(self):
        self.now = 0.0
        self.slept = []

    def clock(self):
        return self.now

    def sleep(self, s):
        self.slept.append(s)
        self.now += s


def recorded(n, every_s):
    out = []
    for i in range(n):
        e = stamped(ev.CardPicked(round=0, turn=i, card=i), session="s1", source="participant", seq=i + 1, time_ns=i)
        out.append(RecordedEvent("pairplay/s1/participant/CardPicked", e, int(i * every_s * 1e9), encode_event(e)))
    return out


def test_speed_divides_the_recorded_gaps():
    bus, t = FakeBus(), FakeTime()
    assert republish(bus, recorded(5, 0.5), speed=2.0, clock=t.clock, sleep=t.sleep) == 5
    assert t.now == 1.0  # 2 s of recording at 2x
    assert [p for _, p in bus.sent] == [r.payload for r in recorded(5, 0.5)]  # the recorded bytes, in order


def test_max_speed_never_waits_and_as_session_moves_the_events():
    bus, t = FakeBus(), FakeTime()
    republish(bus, recorded(3, 10.0), speed=0.0, as_session="s2", clock=t.clock, sleep=t.sleep)
    assert t.slept == []
    assert [k for k, _ in bus.sent] == ["pairplay/s2/participant/CardPicked"] * 3
    assert all(decode_event(p).session == "s2" for _, p in bus.sent)


def test_the_sessions_end_goes_out_after_what_was_filed_after_it_and_as_moves_the_config_too():
    # trial33 L: the robot's last RobotActed filed after SessionEnded were lost by a recorder of the replay, and
    # the SessionStarted's config still named the original session (the copy's verify FAILed)
    from pairplay.schemas.session import SessionConfig
    bus, t = FakeBus(), FakeTime()
    start = stamped(ev.SessionStarted(config=SessionConfig(session="s1", participant="sim:ashley", seed=1, rounds=1)), session="s1",
                    source="game", seq=1, time_ns=0)
    end = stamped(ev.SessionEnded(reason="completed", rounds_played=1), session="s1", source="game", seq=2, time_ns=1)
    late = recorded(2, 0.5)
    events = [RecordedEvent("pairplay/s1/game/SessionStarted", start, 0, encode_event(start)),
              RecordedEvent("pairplay/s1/game/SessionEnded", end, 0, encode_event(end))] + late
    assert republish(bus, events, speed=1.0, as_session="s2", clock=t.clock, sleep=t.sleep) == 4
    sent = [decode_event(p) for _, p in bus.sent]
    assert [type(e).__name__ for e in sent] == ["SessionStarted", "CardPicked", "CardPicked", "SessionEnded"]
    assert t.now == 0.5  # at their recorded times, the end with the last of them
    assert sent[0].config.session == "s2" and {e.session for e in sent} == {"s2"}

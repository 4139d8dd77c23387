"""A replay recorded by a recorder keeps the events its sources sent after the session's end
(trial33 L: the robot's last RobotActed, filed after the game's SessionEnded, were shed: the recorder
closed at the replayed end, as no source of the session was on the bus; `pairplay replay` now is, while
it publishes: services/replayer.py REPLAY_SOURCE). Real processes on a real loopback bus."""

from __future__ import annotations

import dataclasses

from busutil import recorder_process
from cli_zygote import shared
from rewrite_mcap import rewritten

from pairplay.replay.reader import read_log
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.verify import verify_recording

LATE_NS = 300 * 10**9  # after the end, in the recording's time: 3 s at --speed 100 (the recorder looks every 0.3 s)


def late_tail(tmp_path):
    """The sample, its events after SessionEnded (the learner's last RewardGiven) LATE_NS later."""
    ended = []

    def each(channel, message):
        if channel.topic.endswith("/SessionEnded"):
            ended.append(message.log_time)
        elif ended:
            return [dataclasses.replace(message, log_time=message.log_time + LATE_NS,
                                        publish_time=message.publish_time + LATE_NS)]
        return [message]
    return rewritten(tmp_path / "late.mcap", each=each)


def test_a_recorder_keeps_a_replays_events_sent_after_its_session_ended(tmp_path):
    src = late_tail(tmp_path)
    original = read_log(src)
    tail = [r for r in original.events if r.log_time_ns > original.events[0].log_time_ns + LATE_NS]
    assert tail and type(tail[-1].event).__name__ == "RewardGiven"  # (what the test is about is there)
    out = tmp_path / "rec"
    # a router, as the trial's (`pairplay router`): the recorder and the replay are its clients
    with Bus(BusOptions(mode="router")) as hub, recorder_process(hub, "lt1", out) as proc:
        done = shared().run(["replay", str(src), "--as", "lt1", "--speed", "100", "--connect", hub.locators()[0]],
                            tmp_path, timeout=120)
        assert done.returncode == 0, done.stderr
        assert proc.wait(60) == 0
    copy = read_log(out / "lt1.mcap")
    # every event but the original recorder's own (a recorder records its own, not another's: the sample's
    # refusal), the session's end last (services/replayer.py end_last)
    assert sorted((r.event.source, r.event.seq) for r in copy.events if r.event.source != "recorder") == \
        sorted((r.event.source, r.event.seq) for r in original.events if r.event.source != "recorder")
    assert type(copy.events[-1].event).__name__ == "SessionEnded" and not copy.missing
    assert verify_recording(out / "lt1.mcap").ok  # (the trial's copy FAILed: "2 recomputed beyond the recording")


def test_a_live_view_of_a_replay_gets_the_events_sent_after_its_session_ended(tmp_path):
    # the README's pair (view --listen, then replay --as): the view ended 0.5 s after the replayed SessionEnded and
    # saved 2551 of 2552 as whole: the robot's last RobotActed, 1.3 s after the one before it (trial33 L addendum)
    import threading

    from pairplay.services.view.sources import LiveSource
    src = late_tail(tmp_path)
    original = read_log(src)
    with Bus(BusOptions(mode="router")) as hub, Bus(BusOptions(mode="client", listen=[], connect=hub.locators())) as bus:
        source = LiveSource(bus, "lt2", catch_up=False)
        got, stop = [], threading.Event()
        viewer = threading.Thread(target=lambda: got.extend(e for e, _ in source.items(stop) if e is not None))
        viewer.start()
        done = shared().run(["replay", str(src), "--as", "lt2", "--speed", "100", "--connect", hub.locators()[0]],
                            tmp_path, timeout=120)
        viewer.join(60)
        stop.set()
        assert done.returncode == 0, done.stderr
    assert sorted((e.source, e.seq) for e in got) == sorted((r.event.source, r.event.seq) for r in original.events)

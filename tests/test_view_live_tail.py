"""A live view stays for a session's events after its SessionEnded while a source of the session is on the
bus, as the recorder does (trial33 L: a view ended 0.5 s after the end and saved the rest as whole without
the robot's last RobotActed, which came 1.3 s after the one before it). Real Zenoh on loopback."""

from __future__ import annotations

import threading

from busutil import connector, listener, wait_until

from pairplay.replay.reader import read_log
from pairplay.schemas.keys import alive_key
from pairplay.services.view.sources import LiveSource
from rewrite_mcap import SAMPLE


def test_a_live_view_stays_for_a_late_event_while_its_source_is_on_the_bus():
    records = read_log(SAMPLE).events
    assert type(records[-2].event).__name__ == "SessionEnded" and records[-1].event.source == "learner"
    with listener() as session_bus, connector(session_bus) as view_bus:
        token = session_bus.alive(alive_key(records[0].event.session, "learner"))
        source = LiveSource(view_bus, records[0].event.session, catch_up=False)
        got, stop, idle = [], threading.Event(), threading.Event()

        def view():
            for e, _ in source.items(stop, grace_s=0.3):
                got.append(e) if e is not None else idle.set() if source.ended else None
        viewer = threading.Thread(target=view)
        viewer.start()
        assert wait_until(lambda: view_bus.alive_now(alive_key(records[0].event.session, "*")))
        assert wait_until(lambda: session_bus.matching(records[0].key))
        for r in records[:-1]:
            session_bus.put(r.key, r.payload)
        assert wait_until(lambda: len(got) == len(records) - 1 and idle.is_set())
        threading.Event().wait(0.6)  # past the view's grace (0.3 s): the learner still on the bus, its last reward to come
        session_bus.put(records[-1].key, records[-1].payload)
        token.undeclare()
        viewer.join(30)
        stop.set()
    assert len(got) == len(records) and got[-1].seq == records[-1].event.seq

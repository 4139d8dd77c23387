"""A service thread publishes what it decides itself when its Outbox's thread is idle (issue 16:
services/bus.py `Outbox.publish_here`, services/runner.py `Node.step`). That opens a new way for a
thread to wait in a put; these tests show it freezes nothing.

A put blocks for real here: a subscriber process is SIGSTOPped, so its socket stops draining, and
the publisher's BLOCK put waits once Zenoh's queue and the kernel's buffers are full (~18 MiB on
this VM, under a second).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.services.bus import Bus, BusOptions, Outbox
from pairplay.services.runner import Node

SUBSCRIBER = """
import sys, threading
from pairplay.services.bus import Bus, BusOptions
bus = Bus(BusOptions(listen=[], connect=[sys.argv[1]]))
bus.subscribe(sys.argv[2], lambda k, p: None)
print("ready", flush=True)
threading.Event().wait()
"""


@pytest.fixture
def stalled():
    """(bus, key expression) where a matching subscriber process has stopped reading."""
    with Bus() as bus:
        proc = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, bus.locators()[0], "pairplay/**"],
                                stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout.readline().strip() == "ready"
            deadline = time.monotonic() + 30
            while not bus.matching("pairplay/s/board/CardPicked"):
                assert time.monotonic() < deadline, "the subscriber never matched"
                time.sleep(0.01)
            os.kill(proc.pid, signal.SIGSTOP)
            yield bus
        finally:
            proc.kill()
            proc.wait()


def wait_stuck(outbox: Outbox, timeout_s: float = 60.0) -> None:
    """Until something sent stays unpublished for 0.5 s (a put is blocked)."""
    deadline = time.monotonic() + timeout_s
    last, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        n = len(outbox.sent or []), outbox.pending()
        if n != last:
            last, since = n, time.monotonic()
        elif n[1] and time.monotonic() - since > 0.5:
            return
        time.sleep(0.05)
    raise AssertionError("the put never blocked")


class Flood:
    """A logic whose every input makes 4 MiB of output: its Node's put soon waits on the stalled peer."""
    name = "participant"
    consumes = frozenset({"CardPicked"})
    sources: dict = {}
    done = False

    def start(self):
        return []

    def handle(self, e):
        return [ev.MessageRejected(reason="x" * (1 << 20), key="k") for _ in range(4)]


def test_a_service_thread_waiting_in_a_put_holds_up_neither_its_lock_nor_other_publishers_nor_the_shutdown(stalled):
    bus = stalled
    node = Node(bus, Flood(), "s", resume=False)
    stop = threading.Event()
    thread = node.run_in_thread(stop)
    for seq in range(1, 21):  # 80 MiB: far more than the link holds
        pick = stamped(ev.CardPicked(round=0, turn=0, card=0), session="s", source="board", seq=seq, time_ns=seq)
        node.inbox.put(event_key("s", "board", "CardPicked"), encode_event(pick))
    wait_stuck(node.outbox)
    assert thread.is_alive()
    # the session's end (services/session.py end_game) takes the Node's lock: the put is outside it
    t = time.monotonic()
    assert node._lock.acquire(timeout=1.0), "the Node's lock is held by a thread waiting in a put"
    try:
        node.publish(node.driver._stamp([ev.SessionEnded(reason="interrupted")]))  # another thread: queued
    finally:
        node._lock.release()
    took = time.monotonic() - t
    assert took < 0.5, took
    # the shutdown: every step bounded however long the put waits
    stop.set()
    t = time.monotonic()
    assert node.close(0.3) is False  # not all could go out: said, not waited for
    bus.close(0.5)
    took = time.monotonic() - t
    assert took < 1.5, took


def test_an_owner_publishing_itself_and_other_threads_sending_keep_one_order_and_lose_nothing():
    got: list[bytes] = []
    with Bus() as bus:
        done = threading.Event()
        bus.subscribe("t/**", lambda _k, p: (got.append(p), len(got) == 4000 and done.set()))
        outbox = Outbox(bus, "t", keep=True)

        def owner():
            for i in range(2000):
                outbox.send("t/o", b"o%d" % i, wake=False)
                outbox.publish_here()

        def other():
            for i in range(2000):
                outbox.send("t/h", b"h%d" % i)
        threads = [threading.Thread(target=owner), threading.Thread(target=other)]
        for th in threads:
            th.start()
        for th in threads:
            th.join(60)
        assert outbox.flush(30)
        assert done.wait(30), len(got)
        outbox.close(1.0)
    assert got == [p for _, p in outbox.sent]  # published in one order, delivered in it
    assert [p for p in got if p[:1] == b"o"] == [b"o%d" % i for i in range(2000)]
    assert [p for p in got if p[:1] == b"h"] == [b"h%d" % i for i in range(2000)]


class SpyBus(Bus):
    """A real bus that also notes how each event left: ('batched' | 'express', key)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.calls: list[tuple[str, str]] = []

    def put(self, key, payload):
        self.calls.append(("express", key))
        super().put(key, payload)

    def put_batched(self, key, payload):
        self.calls.append(("batched", key))
        super().put_batched(key, payload)


def test_the_events_of_one_step_leave_in_one_batch_that_their_last_sends():
    """One input's outputs (a first pick: CardRevealed, CardObserved, SuggestionRequested) go into
    Zenoh's batch without express and the last one, express, sends them all at once (issue 16:
    three express puts to a peer took 98 us of the publishing thread, one batch 29 us). Each
    arrives, in order, at a subscriber in another Zenoh session, and a lone event is express."""
    with SpyBus() as bus, Bus(BusOptions(listen=[], connect=bus.locators())) as peer:
        got: list[tuple[str, bytes]] = []
        arrived = threading.Event()
        peer.subscribe("t/**", lambda k, p: (got.append((k, p)), len(got) == 4 and arrived.set()))
        deadline = time.monotonic() + 30
        while not bus.matching("t/a"):
            assert time.monotonic() < deadline, "the peer never matched"
            time.sleep(0.01)
        outbox = Outbox(bus, "t", keep=True)
        for key in ("t/a", "t/b", "t/c"):
            outbox.send(key, key.encode(), wake=False)
        outbox.publish_here()
        outbox.send("t/d", b"t/d", wake=False)
        outbox.publish_here()
        assert arrived.wait(30), got
        outbox.close(1.0)
    assert bus.calls == [("batched", "t/a"), ("batched", "t/b"), ("express", "t/c"), ("express", "t/d")]
    assert got == [(k, k.encode()) for k in ("t/a", "t/b", "t/c", "t/d")]
    assert outbox.sent == got  # what a restarted recorder is told was sent


def test_a_recovering_bus_sends_every_event_on_its_one_publisher_per_key():
    """A recovering bus's advanced publishers keep the cache a late joiner is sent, one per key:
    a second, batched publisher on the key would split it (services/bus.py Bus.put_batched)."""
    with Bus(BusOptions(recovery=True)) as bus:
        bus.put_batched("t/a", b"1")
        assert "t/a" in bus._publishers and not bus._batched

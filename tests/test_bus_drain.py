"""A drained subscription (services/bus.py `Bus.subscribe(drain=True)`, the recorder's): one thread
of ours takes every sample waiting in a Zenoh FIFO channel at once. It must hand on every sample in
the order it came, survive a callback that raises, end when its subscriber or its session closes,
and do the same on a recovering bus (an advanced subscriber behind a router)."""

from __future__ import annotations

import threading
import time

import pytest

from pairplay.services.bus import DRAIN_CAPACITY, Bus, BusOptions

from busutil import connector, listener, wait_until


def takers() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t.name.startswith("pairplay-take-")}


@pytest.mark.parametrize("recovering", [False, True], ids=["peer", "recovering"])
def test_every_sample_in_order_across_processes_then_the_thread_ends(recovering):
    n = 5 * DRAIN_CAPACITY  # more than the channel holds: the thread must keep taking while they come
    before = takers()
    with Bus(BusOptions(mode="router")) as router:
        options = BusOptions(mode="client", listen=[], connect=router.locators(), recovery=recovering)
        with Bus(options) as sub_bus, Bus(options) as pub_bus:
            got: list[tuple[str, bytes]] = []
            sub_bus.subscribe("drain/**", lambda k, p: got.append((k, p)), drain=True)
            mine = takers() - before
            assert len(mine) == 1
            assert wait_until(lambda: pub_bus.matching("drain/a"))
            for i in range(n):
                pub_bus.put("drain/a" if i % 2 else "drain/b", i.to_bytes(4, "big"))
            assert wait_until(lambda: len(got) == n), f"{len(got)} of {n} samples taken"
            assert [int.from_bytes(p, "big") for _, p in got] == list(range(n))
            assert {k for k, _ in got} == {"drain/a", "drain/b"}
        # the subscriber's session closed: its thread has ended (not left waiting on a channel)
        assert wait_until(lambda: not any(t.is_alive() for t in mine), 5.0)


def test_a_callback_that_raises_does_not_stop_the_thread():
    with listener() as a, connector(a) as b:
        got: list[bytes] = []

        def callback(_key: str, payload: bytes) -> None:
            if payload == b"bad":
                raise ValueError("hostile")
            got.append(payload)
        sub = b.subscribe("drain/**", callback, drain=True)
        assert wait_until(lambda: a.matching("drain/x"))
        for p in (b"1", b"bad", b"2", b"bad", b"3"):
            a.put("drain/x", p)
        assert wait_until(lambda: got == [b"1", b"2", b"3"]), got
        mine = {t for t in takers() if t.is_alive()}
        t0 = time.monotonic()
        sub.undeclare()  # the subscriber alone, its session still open
        assert wait_until(lambda: not any(t.is_alive() for t in mine), 5.0)
        assert time.monotonic() - t0 < 1.0

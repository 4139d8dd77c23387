"""Zenoh's own log stays off a verb's stdout, and pairplay gives Zenoh nothing to log at a shutdown.

Before: an interrupted `pairplay session` printed Zenoh's ERROR "sending on a closed channel" on its
stdout now and then (~1 in 5 of test_cli_logging's interrupted session on a loaded CI). Two faults:
Zenoh's log was on by default (errors), and Zenoh writes it to stdout; and a get whose reader stopped
early (a shutdown's `stop` in `alive_now`/`query`, `locators` once it had its answer) dropped Zenoh's
FifoChannel while the query went on, so each later reply was that ERROR. Each check runs in a process
of its own: Zenoh's log is set up once per process, and it writes to the process's file descriptor 1."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

CLOSED = "sending on a closed channel"

# a peer with liveliness tokens and a queryable that answers late; a client asks both and stops reading
# at once (its `stop` set), or, for `locators`, once it has its answer; then replies keep coming
EARLY_READERS = textwrap.dedent("""
    import threading, time
    from pairplay.services.bus import Bus, BusOptions
    stop = threading.Event()
    stop.set()
    with Bus(BusOptions()) as a:
        ep = a.locators()
        tokens = [a.alive(f"zlog/alive/{i}") for i in range(20)]
        a.queryable("zlog/q", lambda q: threading.Timer(0.1, lambda: Bus.answer(q, [b"x"] * 5)).start())
        with Bus(BusOptions(mode="client", connect=ep)) as b:
            time.sleep(0.3)
            for _ in range(5):
                assert b.alive_now("zlog/alive/*", timeout_s=1.0, stop=stop) == set()
                assert b.query("zlog/q", timeout_s=1.0, stop=stop) == []
                b.locators(), a.locators()  # a client listens nowhere: its list is empty
            assert len(b.alive_now("zlog/alive/*", timeout_s=2.0)) == 20  # a reader that waits gets them all
            assert b.query("zlog/q", timeout_s=2.0) == [b"x"] * 5
            # a drained subscription closed while a peer publishes into it
            got = []
            b.subscribe("zlog/s", lambda k, p: got.append(p), drain=True)
            time.sleep(0.3)
            for i in range(200):
                a.put("zlog/s", b"y")
            b.close()
            for i in range(200):
                a.put("zlog/s", b"y")
        time.sleep(0.5)  # the late replies arrive
    print("done")
""")


def run(script: str, **env) -> subprocess.CompletedProcess:
    environ = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          env=dict(environ, **env))


def test_a_get_whose_reader_stops_early_leaves_zenoh_no_closed_channel_to_send_into():
    # Zenoh's errors on (RUST_LOG): what it would say, whichever stream it says it on
    r = run(EARLY_READERS, RUST_LOG="error")
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.splitlines() == ["done"], r.stdout[-2000:]
    assert CLOSED not in r.stdout + r.stderr


# Zenoh logs an ERROR of its own: a FifoChannel dropped while its query's replies still come
ZENOH_ERROR = textwrap.dedent("""
    import threading, time
    import zenoh
    from pairplay.services.bus import Bus, BusOptions
    with Bus(BusOptions()) as a:
        a.queryable("zlog/q", lambda q: threading.Timer(0.1, lambda: Bus.answer(q, [b"x"])).start())
        replies = a.session.get("zlog/q", handler=zenoh.handlers.FifoChannel(8), timeout=1.0)
        del replies
        time.sleep(0.5)
""")


def test_zenohs_log_stays_off_stdout_unless_asked_for_with_rust_log():
    r = run(ZENOH_ERROR)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout == "" and r.stderr == "", (r.stdout[-2000:], r.stderr[-2000:])
    # asked for: Zenoh's log, where Zenoh writes it (stdout: zenoh-python offers no other stream; docs/bus.md)
    r = run(ZENOH_ERROR, RUST_LOG="error")
    assert r.returncode == 0 and CLOSED in r.stdout, (r.stdout[-2000:], r.stderr[-2000:])

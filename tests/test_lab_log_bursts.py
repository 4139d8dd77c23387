"""The lab server's per-client lines come in bursts, and uvicorn's lines in pairplay's words.

Rule (services/lab/serverlog.py): the first line of a kind from a client is said at once, the next ones are
counted and said in one line when the client has gone quiet, every EVERY_S while they go on, or when the server
stops (`flush`); uvicorn's records are said by "pairplay.lab". The real server's flood is
tests/test_slow_requests.py; here the burst's bookkeeping, on a real event loop with its timers run by hand
(no time is waited or asserted: a quiet or an every of 0 s is due at once).
"""

from __future__ import annotations

import asyncio
import logging

from pairplay.services.lab.serverlog import Bursts, quiet_uvicorn


def _more(n: int) -> str:
    return f"{n} more from 10.0.0.9"


def _lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "pairplay.lab"]


def test_the_first_is_said_at_once_and_the_rest_counted_until_the_stop(caplog):
    caplog.set_level(logging.WARNING)
    bursts = Bursts(logging.getLogger("pairplay.lab"), quiet_s=3600, every_s=3600)
    loop = asyncio.new_event_loop()
    try:
        for _ in range(200):
            bursts.said(loop, ("no head", "10.0.0.9"), "first from 10.0.0.9", _more)
        bursts.said(loop, ("no head", "10.0.0.8"), "first from 10.0.0.8", _more)  # another client: its own
        assert _lines(caplog) == ["first from 10.0.0.9", "first from 10.0.0.8"]
        bursts.flush()  # the server stops: what is counted is said, nothing is lost
        bursts.flush()  # said once
    finally:
        loop.close()
    assert _lines(caplog) == ["first from 10.0.0.9", "first from 10.0.0.8", "199 more from 10.0.0.9"]


def test_a_quiet_client_has_its_count_said_and_its_next_one_is_a_new_burst(caplog):
    caplog.set_level(logging.WARNING)
    bursts = Bursts(logging.getLogger("pairplay.lab"), quiet_s=0.0, every_s=3600)
    loop = asyncio.new_event_loop()
    try:
        key = ("no head", "10.0.0.9")
        bursts.said(loop, key, "first from 10.0.0.9", _more)
        bursts.said(loop, key, "first from 10.0.0.9", _more)
        bursts._due(loop, key)  # the timer `said` set (quiet already: 0 s)
        bursts.said(loop, key, "first from 10.0.0.9", _more)
        bursts._due(loop, key)  # nothing counted: over, without a line
        bursts.flush()
    finally:
        loop.close()
    assert _lines(caplog) == ["first from 10.0.0.9", "1 more from 10.0.0.9", "first from 10.0.0.9"]


def test_a_burst_that_goes_on_has_its_count_said_every_so_often(caplog):
    caplog.set_level(logging.WARNING)
    bursts = Bursts(logging.getLogger("pairplay.lab"), quiet_s=3600, every_s=0.0)
    loop = asyncio.new_event_loop()
    try:
        key = ("no head", "10.0.0.9")
        bursts.said(loop, key, "first from 10.0.0.9", _more)
        for n in (3, 2):
            for _ in range(n):
                bursts.said(loop, key, "first from 10.0.0.9", _more)
            bursts._due(loop, key)  # not quiet: said, and the burst goes on (the next one is counted)
        bursts.flush()
    finally:
        loop.close()
    assert _lines(caplog) == ["first from 10.0.0.9", "3 more from 10.0.0.9", "2 more from 10.0.0.9"]


def test_uvicorns_own_lines_are_said_by_pairplays_logger(caplog, capfd):
    caplog.set_level(logging.WARNING)
    quiet_uvicorn()
    logging.getLogger("uvicorn.error").warning("Something uvicorn says.")
    logging.getLogger("uvicorn.error").warning("Invalid HTTP request received.")  # the lab's protocol says it
    try:
        raise ValueError("a fault")
    except ValueError:
        logging.getLogger("uvicorn.error").exception("Exception in ASGI application\n")
    said = [(r.name, r.getMessage(), r.exc_info is not None) for r in caplog.records]
    assert said == [("pairplay.lab", "the web server (uvicorn) says: Something uvicorn says.", False),
                    ("pairplay.lab", "a request failed inside the lab server, answered 500 (a fault of pairplay's)",
                     True)]
    assert "uvicorn" not in capfd.readouterr().err.replace("(uvicorn)", "")

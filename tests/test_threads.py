"""Independent games on two threads give the bytes of one thread (core/threads.py, core/simulate.py)."""

import numpy as np
import pytest

from pairplay.core import simulate, threads
from pairplay.core.personas import PERSONAS
from pairplay.schemas.config import LearnerConfig


def test_each_runs_every_piece_once_and_raises_the_first_error():
    seen = []
    threads.each(seen.append, 50, workers=2)
    assert sorted(seen) == list(range(50))
    threads.each(seen.append, 0, workers=2)

    def fail(i):
        if i in (3, 7):
            raise ValueError(i)
    with pytest.raises(ValueError, match="3"):
        threads.each(fail, 10, workers=1)
    with pytest.raises(ValueError):
        threads.each(fail, 10, workers=2)


def test_the_main_thread_runs_no_piece_and_a_signal_stops_its_wait_at_once():
    """A piece is compiled code holding no GIL for seconds; on the main thread it held off Ctrl-C until it
    returned (`pairplay study`: 2.7-9.9 s to exit). The main thread now only waits, and its wait is interrupted."""
    import signal
    import threading

    ran_on = []
    threads.each(lambda i: ran_on.append(threading.current_thread()), 8, workers=2)
    threads.each(lambda i: ran_on.append(threading.current_thread()), 3, workers=1)
    assert len(ran_on) == 11 and threading.main_thread() not in ran_on

    class Stop(Exception):
        pass

    def handler(signum, frame):
        raise Stop()

    release, started, released = threading.Event(), threading.Semaphore(0), []

    def piece(i):
        started.release()
        released.append(release.wait(30))  # True: let go by the test; False: waited out its 30 s

    def interrupt():
        started.acquire()
        started.acquire()  # both pieces are running
        signal.pthread_kill(threading.main_thread().ident, signal.SIGUSR1)

    before = signal.signal(signal.SIGUSR1, handler)
    try:
        threading.Thread(target=interrupt, daemon=True).start()
        with pytest.raises(Stop):
            threads.each(piece, 4, workers=2)
    finally:
        signal.signal(signal.SIGUSR1, before)
        release.set()
    deadline = threading.Event()
    while len(released) < 2 and not deadline.wait(0.01):
        pass
    assert released == [True, True]  # interrupted while both pieces still ran; no piece started after


def _run(monkeypatch, workers, **kw):
    monkeypatch.setattr(threads, "WORKERS", workers)
    personas = [p for p in list(PERSONAS.values())[:3] for _ in range(12)]
    seeds = list(range(len(personas)))
    return simulate.run_games(personas, seeds, 7, LearnerConfig(), progress=lambda done: None, **kw)


@pytest.mark.parametrize("kw", [dict(record="all", snapshot_every=2), dict(mode="fixed", policy=np.arange(24) % 88,
                                                                            record="considerable")])
def test_a_batch_on_two_threads_equals_one_thread(monkeypatch, kw):
    one, two = _run(monkeypatch, 1, **kw), _run(monkeypatch, 2, **kw)
    assert len(simulate._pieces(36)) > 1  # the two-thread run really was in pieces
    for a, b in zip(one[:6], two[:6]):
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
    assert np.array_equal(one.trace.rows, two.trace.rows) and np.array_equal(one.trace.order, two.trace.order)


def test_a_trace_that_fills_up_mid_round_is_grown_and_the_round_resumed(monkeypatch):
    """core/kernels.py `_play_round` stops when the trace is full and `play` resumes the round in a
    bigger one: from an empty buffer (0 rows per game and round), grown at 0, 1,024 and 3,072 rows
    (mid-round), the trace and the games are those of a roomy buffer."""
    monkeypatch.setattr(threads, "WORKERS", 1)
    personas = [p for p in list(PERSONAS.values())[:3] for _ in range(12)]

    def run():
        return simulate.run_games(personas, list(range(len(personas))), 7, LearnerConfig(), record="all",
                                  snapshot_every=2)
    roomy = run()
    monkeypatch.setattr(simulate, "TRACE_ROWS", 0)
    grown = run()
    assert len(grown.trace.rows) > 3072
    for a, b in zip(roomy[:6], grown[:6]):
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
    assert np.array_equal(roomy.trace.rows, grown.trace.rows)

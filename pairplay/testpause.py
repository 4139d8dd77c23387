"""A test-only pause at a named moment of a verb: how a test lands a real signal in a window of milliseconds.

Rule: `pause(moment)` does nothing unless the environment names that moment,
`PAIRPLAY_TEST_PAUSE=<moment>:<go-file>` (several joined by `;`: a first signal at one, a second at another); then it says `pairplay-test: paused at <moment>` on stderr and
waits until <go-file> exists (the test sends its signal, then makes the file). The wait is a plain sleep,
so a signal meets whatever handler is in place at that moment, as it would in a real run that happened to
be there (tests/test_cut_signals.py). Nobody sets the variable in use; its moments are named where they are
(`grep -rn "testpause.pause" .`). Imports nothing but `os` and `time` when called.
"""

from __future__ import annotations

VARIABLE = "PAIRPLAY_TEST_PAUSE"
POLL_S = 0.02  # how often the go-file is looked for


def pause(moment: str) -> None:
    """Wait here until the test's go-file exists, if the environment names `moment` (module rule)."""
    import os

    named = next((m for m in os.environ.get(VARIABLE, "").split(";") if m.startswith(moment + ":")), "")
    if not named:
        return
    import sys
    import time

    go = named[len(moment) + 1:]
    # one write, the line and its end: print's two writes interleaved with another thread's pause (a test holds two
    # threads at once: tests/test_cut_signals.py) into "...signal-stoppingpairplay-test: paused at ...", and the
    # test never saw its moment
    sys.stderr.write(f"pairplay-test: paused at {moment}\n")
    sys.stderr.flush()
    while not os.path.exists(go):
        time.sleep(POLL_S)

"""Progress bars of the verbs that work for a while (study, sweep): one way to make them.

Rule: a bar is drawn only on a terminal: when stderr is not a tty (a pipe, a file,
a CI log, a test's capture) or the verb was given `-q/--quiet`, no bar is made and
stderr holds only the verb's lines; tqdm's own TQDM_DISABLE=1 turns them off on a
terminal too. Before, `pairplay sweep 2>log` wrote tqdm's
redraws (carriage returns, one per cell) into the log ahead of its interrupted line,
and `pairplay study` did the same. Every tqdm of the command line is made here.
"""

from __future__ import annotations

import os
import sys


def shown(quiet: bool) -> bool:
    """Whether a progress bar is drawn: not --quiet, not turned off by tqdm's own TQDM_DISABLE
    environment variable (its documented override: our explicit `disable` would hide it), and
    stderr is a terminal."""
    if quiet or os.environ.get("TQDM_DISABLE", "").strip().lower() in ("1", "true", "yes", "on"):
        return False
    stream = sys.stderr
    try:
        return stream is not None and stream.isatty()
    except (AttributeError, ValueError):  # a replaced or closed stream: no terminal
        return False


def bar(total: int, desc: str, unit: str, quiet: bool, **options):
    """A tqdm bar on stderr of `total` `unit`s, disabled unless `shown(quiet)` (module rule);
    `options` go to tqdm (initial, leave)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not shown(quiet), file=sys.stderr,
                dynamic_ncols=True, **options)

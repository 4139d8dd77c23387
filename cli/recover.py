"""`pairplay recover REC`: complete a recording a crash cut short (replay/recover.py).

Rule: writes REC's readable records into a complete, indexed file (default
<stem>.recovered.mcap beside it, or -o), and what the recorder's journal beside
it (REC.journal, replay/wal.py) holds that REC lacks, through the live checks
(services/walmerge.py), saying how many it took; the original is never modified, an
existing output is replaced only with --force, and the output appears only
when complete. Exit 0 when the output is complete, 2 (one line on stderr,
nothing written) when REC is missing, empty or not MCAP (a file of nothing
with its journal beside it, as a recorder killed before its first flush leaves
it, is completed from the journal), holds no session
(only MCAP's magic or header, another program's MCAP, no SessionStarted:
replay/check.py `no_session`), or the output exists.
"""

from __future__ import annotations

import argparse
import logging

from pairplay.cli.args import add_force

log = logging.getLogger("pairplay.recover")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="REC")
    p.add_argument("-o", "--output", help="output file (default <stem>.recovered.mcap beside REC)")
    add_force(p, "an existing output file")


def run(args: argparse.Namespace) -> int:
    from pairplay.replay.recover import recover
    from pairplay.services.walmerge import admit

    done = recover(args.recording, args.output, force=args.force, admit=admit)
    if done.damaged:
        state = f"damaged ({done.reason}); every intact part kept"
    elif done.truncated:
        state = f"cut short ({done.reason})"
    else:
        state = "complete already"
    ended = "" if done.ended else "; the session's end was not recorded (partial session)"
    if not done.started:
        ended = "; its SessionStarted is not in it (lost, or never recorded): no session to rebuild or verify"
    journal = ""
    if done.journal is not None:
        journal = (f"; {done.from_journal} events taken from its journal {done.journal.name}"
                   f"{f', {done.journal_refused} of its messages refused (recorded as refusals)' if done.journal_refused else ''}"
                   f"{f' (read up to its torn tail: {done.journal_torn})' if done.journal_torn else ''}")
    print(f"{args.recording}: {state}; {done.messages} messages kept in {done.output}{journal}{ended}")
    if done.journal_error:  # what it held (up to the last 5 ms before a crash) is not in the output: said, not silent
        log.warning("recover: the journal beside %s is unreadable, none of its records were used: %s",
                    args.recording, done.journal_error)
    return 0

"""`pairplay recover REC`: complete a recording a crash cut short (replay/recover.py).

Rule: writes REC's readable records into a complete, indexed file (default
<stem>.recovered.mcap beside it, or -o); the original is never modified. Exit 0
when the output is complete, 2 when the input cannot be read at all.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="REC")
    p.add_argument("-o", "--output", help="output file (default <stem>.recovered.mcap)")


def run(args: argparse.Namespace) -> int:
    from pairplay.replay.recover import recover

    try:
        done = recover(args.recording, args.output)
    except (OSError, ValueError) as err:
        print(f"pairplay recover: {err}", file=sys.stderr)
        return 2
    state = f"cut short ({done.reason})" if done.truncated else "complete already"
    print(f"{args.recording}: {state}; {done.messages} messages kept in {done.output}")
    return 0

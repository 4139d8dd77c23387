"""Serve the view of a recording stopped mid-turn, for the picture in docs/view.png.

Rule: the view folds the recording up to the last suggestion the participant
considered and found consistent (or the `--suggestion`-th last) (cards face up and matched, the observed card, the matching card and
the candidate set highlighted, the Q-table as learned so far), then serves it
with `pairplay view`'s own output code on 127.0.0.1 until killed. A browser
(headless Chromium, tools/view_screenshot.py) then photographs the web viewer.

  python tools/view_picture.py REC.mcap --grpc-port 19876 --web-port 19090
"""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.services.bus import stop_on_signals
from pairplay.services.view.output import ViewOutput, finish, open_stream
from pairplay.services.view.rerun_logger import RerunView


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("recording", type=Path)
    p.add_argument("--suggestion", type=int, default=0,
                   help="stop after the n-th last suggestion the participant considered (0: the last)")
    p.add_argument("--grpc-port", type=int, default=19876)
    p.add_argument("--web-port", type=int, default=19090)
    args = p.parse_args(argv)
    events = [r.event for r in read_log(args.recording).events]
    considered = [i for i, e in enumerate(events) if isinstance(e, ev.SuggestionPerceived)
                  and e.considered and e.consistent and not e.from_memory]
    if not considered:
        p.error("the recording has no suggestion the participant considered")
    cut = considered[-1 - min(args.suggestion, len(considered) - 1)] + 1
    rec, where = open_stream(ViewOutput(rrd=None, serve=True, grpc_port=args.grpc_port, web_port=args.web_port))
    view = RerunView(rec)
    for e in events[:cut]:
        view.handle(e)
    view.close()  # logs the Q-table as it stands and flushes
    print("\n".join(where), flush=True)
    stop = threading.Event()
    stop_on_signals(stop)
    while not stop.wait(0.5):
        pass
    finish(rec)
    return 0


if __name__ == "__main__":
    sys.exit(main())

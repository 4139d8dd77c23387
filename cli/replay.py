"""`pairplay replay REC`: re-publish a recording on the bus, or --verify it.

Rule: replay publishes every recorded message, byte for byte, on its own key,
in file order but for the session's end, published after the events filed after
it (a recorder or view of the replay kept none of them: services/replayer.py), paced by the recorded log times divided by --speed (1 = as it
happened; `max` = as fast as the bus takes them, BLOCK publishers, nothing
dropped), so the viewer shows it as if live. `--as SESSION` re-publishes under
another session id (the envelope's session is rewritten), so a replay never
collides with a live session of the same id (its SessionStarted's config names it too). `--verify` does not touch the bus:
fresh services are fed the recorded inputs and every derived event must equal
the recorded one (services/verify.py); exit 1 if any differs. Its last line
is the verdict: `verify: PASS` for a whole session, `verify: PASS up to where
the session stopped (...)` for one stopped early, `verify: PASS as far as the
file goes: the file is cut, the session's end is missing (...)` for a file cut
by a crash (also after `pairplay recover`, unless the recorder's journal it read
gave back the session's end: reader.journal_restored): exit 0 for these (what the file
holds is right), and the line says what is missing. Replay's first
line names its bus endpoint, so a view can attach (`pairplay view --session S
--connect ENDPOINT`: it misses what was replayed before it joined, and says so);
to view a replay whole, the view starts first and the replay joins it (`view
--session S --listen E`, then `replay REC --as S --connect E`: README). A REC that is missing, empty, not MCAP or without events
or holding no session (no SessionStarted: replay/check.py `read_session`) is
refused (one line on stderr, exit 2), in both modes; `--verify` also refuses
a file cut (or without its session's end) before its first round ended
(replay/check.py `no_whole_round`: it said "PASS as far as the file goes",
exit 0, about no whole round).
"""

from __future__ import annotations

import argparse
import sys
import time

from pairplay import signals
from pairplay.cli.args import session_id, speed
from pairplay.errors import InputError, OptionError, escaped
from pairplay.livelock import LIVE, is_live
from pairplay.numbers import counted


def add_arguments(p: argparse.ArgumentParser) -> None:
    from pairplay.services.bus import add_bus_arguments

    p.add_argument("recording", metavar="REC")
    p.add_argument("--speed", type=speed, default=None, help="N times real time (0.0001..1000000), or 0 or max: as fast as possible (default 1)")
    p.add_argument("--as", dest="as_session", metavar="SESSION", type=session_id,
                   help="re-publish under this session id")
    p.add_argument("--verify", action="store_true", help="re-run fresh services on the recorded inputs and compare; exit 0 PASS (the last line says if "
                        "the session stopped early or the file is cut, and how far it verified), 1 FAIL")
    add_bus_arguments(p)


def run(args: argparse.Namespace) -> int:
    from pairplay.replay.check import read_session

    if args.verify:  # (an option of the replay on the bus given with --verify did nothing, without a word: a trial)
        given = [o for o, v in (("--speed", args.speed), ("--as", args.as_session)) if v is not None]
        if given:
            raise OptionError(f"--verify re-runs the recording's services here, off the bus: {' and '.join(given)} "
                              f"{'apply' if len(given) > 1 else 'applies'} to a replay on the bus only; give one "
                              "or the other", given[0])
    if args.verify:
        from pairplay.replay.check import session_events
        from pairplay.services.verify import SHOWN, reach_of, verify_read

        # read once, its events alone kept (a 5,000-round file's records, events and bytes were read whole here, and
        # kept while verify read it again: 1.6 GB); a file holding no session is one line on stderr, exit 2
        v = verify_read(args.recording, *session_events(args.recording))
        beyond = ("the damaged part, not compared" if v.lost_part else
                  "where the session stopped, not compared" if v.excused else "the recording")
        for c in v.checks:
            state = "ok" if c.ok(v.excused) else "DIFFERS"
            print(f"{c.service:12s} {c.compared:7d} derived events compared: {state}"
                  f"{'' if not c.extra else f' ({c.extra} recomputed beyond {beyond})'}")
            for m in c.mismatches[:SHOWN]:  # (a recording's values: a session's name may hold anything)
                print(f"    {escaped(m)}")
            if len(c.mismatches) > SHOWN:
                print(f"    ... and {counted(len(c.mismatches) - SHOWN, 'more difference')}")
            for b in c.beyond:  # what was recomputed and is not in the file (a FAIL named none of them)
                print(f"    recomputed, not in the recording: {escaped(b)}")
            if c.extra > len(c.beyond):
                print(f"    ... and {c.extra - len(c.beyond)} more recomputed")
        if v.unknown:
            print(f"{counted(sum(v.unknown.values()), 'event')} of types this version does not know, not compared: "
                  + escaped(", ".join(f"{tag} ({n})" for tag, n in sorted(v.unknown.items()))))
        if v.truncated and not v.ended and is_live(args.recording):
            print(f"the file {LIVE}: verified as far as it goes; verify it again once the session has ended")
        elif v.truncated and not v.ended and v.source_cut:  # a whole copy of a cut file: its source's cut, in the
            print(f"the session's end is missing: {escaped(v.source_cut)}")  # reader's words (reader.EventLog.source_cut)
        elif v.truncated and not v.ended:
            print("the file is cut (a crash?): the session's end is missing; its last events were lost")
        if v.error:
            print(f"error: {escaped(v.error)}")
        from pairplay.cli.main import left_journals
        left_journals("replay", [args.recording])  # what the file lacks that its journal holds, and how to add it
        # (a FAIL of the whole session verified none of it: "verified the whole session" before "verify: FAIL" read
        # as a pass, trial33 E; a FAIL for a damaged part did verify up to it)
        print(escaped(f"{'compared' if not v.ok and v.reach == reach_of(None, v.rounds, '') else 'verified'} "
                      f"{v.reach}"))
        print(escaped(v.verdict))
        return 0 if v.ok else 1  # PASS of what the file holds, even cut or stopped early (services/verify.py)

    import threading

    from pairplay.services.bus import Bus, Outbox, options_from_args, shutdown_wait, stop_on_signals
    from pairplay.services.replayer import republish

    # read whole, not streamed: what the file lost is said before the first event is published, and is known only
    # at its end; then republished from this one read (a second could differ: a recover beside it)
    log = read_session(args.recording)  # a file holding no session is one line on stderr, exit 2
    if not log.events:
        raise InputError(f"holds no events to replay{' (' + log.brief + ')' if log.brief else ''}", args.recording)
    from pairplay.cli.main import left_journals, warn

    # warnings about the result, on stderr, -q or not (cli/main.py: they were on stdout)
    if log.missing:  # what a damaged or cut file, or messages that do not decode, lost: not re-published, said
        warn("replay", f"{args.recording}: not whole ({log.missing}); replaying the "
                       f"{counted(len(log.events), 'event')} of its intact parts")
    elif log.loss_free:  # damaged where no event was: every event replayed, the damage said (reader.EventLog.loss_free)
        warn("replay", f"{args.recording}: {log.loss_free}")
    left_journals("replay", [args.recording])
    stop = threading.Event()
    stop_on_signals(stop)
    with Bus(options_from_args(args), stop=stop) as bus:
        # a view attaches here: pairplay view --session S --connect <this endpoint>
        sessions = {args.as_session} if args.as_session else {r.event.session for r in log.events}
        print(f"replaying session {escaped(', '.join(sorted(sessions)))}; bus listening on "
              f"{bus.listening()}", flush=True)
        t0 = time.perf_counter()
        outbox = Outbox(bus, "replay")  # a publish that waits on a slow subscriber never holds up a signal
        n = republish(outbox, log.events, 1.0 if args.speed is None else args.speed, stop, args.as_session)
        if not outbox.close(shutdown_wait(stop, 30.0, reserve=0.2)):
            n -= outbox.pending()
        took = time.perf_counter() - t0
    stopped = f"; stopped by {signals.said(stop.why)} after {n} of {len(log.events)}" if getattr(stop, "why", "") else ""
    # interrupted, the line goes to stderr, as every verb's (stdout holds results only); -q leaves out the
    # summary of a replay that went through (cli/main.py QUIET_SUMMARIES)
    if stopped or not getattr(args, "quiet", False):
        print(f"{'pairplay replay: ' if stopped else ''}replayed {counted(n, 'event')} in {took:.2f} s ({n / max(took, 1e-9):.0f}/s){stopped}",
              file=sys.stderr if stopped else sys.stdout)
    return 0

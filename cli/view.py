"""`pairplay view`: watch a session live on the bus, or a recording, in rerun.

Rule: the view only subscribes and draws; it never publishes, so it cannot
change a session. It saves an .rrd by default (headless, nothing listens on
the network); `--serve` adds rerun's web viewer, `--spawn` the native viewer.
An existing .rrd is replaced only with --force and the .rrd appears under its
name only when the view is complete (its source ended); a recording without
events (of the --session asked for) is refused and nothing is saved; a taken
--grpc-port/--web-port is refused before anything starts; an .rrd that cannot
be written is one line naming the user's path, never our temporary one.
A signal (exit 130/143, cli/main.py) before the source ended keeps what was
drawn as `<stem>.partial.rrd` (a partial view of a live session may be
wanted; it never takes the complete view's name, and its event log says it is
partial); before the first event nothing is saved. A recording its recorder
is still writing (pairplay/livelock.py) is drawn as far as it goes and saved
as `<stem>.partial.rrd` too, the result line saying the recording is live (it
was saved as `<stem>.rrd`, a part passed off as the whole), and so is a
damaged recording that lost events in its middle or holds messages that do
not decode (reader.EventLog.lost; rebuild's rule: never passed off as whole),
its result line saying it is partial and a line on stderr naming the damage (a
damage that lost no event too), -q or not (cli/main.py `warn`); so is a live view
that never got some of the session's events (joined a session or replay under way
with no recorder's log: a source's seq above 1, services/view/sources.py). Output: one line of result
on stdout (saved); interrupted, its one line goes to stderr, as every verb's;
what the view does is INFO (-v); what it noticed (a malformed message, a gap)
is a WARNING.
Rerun's usage analytics stay off for anything the view starts (view_output).

  pairplay view --recording recordings/s1.mcap              # -> recordings/s1.rrd
  pairplay view --recording REC --speed 1 --serve           # paced, in the browser
  pairplay view --session s1 --connect tcp/127.0.0.1:7447   # live
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import logging
import os
import signal
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

from pairplay import signals
from pairplay.cli.args import (add_force, file_in, float_at_least, int_at_least, output_file, port_or_any,
                                session_id, speed)
from pairplay.errors import InputError, OptionError, OutputError, UserError, escaped, folded
from pairplay.livelock import LIVE, is_live
from pairplay.outputs import NO_HARD_LINKS, check_output, hold, output_path
from pairplay.cli.main import left_journals, warn
from pairplay.replay.check import session_events
from pairplay.services.bus import add_bus_arguments
from pairplay.services.view import DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT, RrdWriteFailed  # without loading rerun (slow)
from pairplay.numbers import counted

log = logging.getLogger("pairplay.view")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_argument_group("what to view")
    src.add_argument("--session", type=session_id, help="session id: view it live on the bus (or pick it from a recording)")
    src.add_argument("--recording", type=Path, metavar="REC", help="an MCAP recording to view instead of the bus")
    src.add_argument("--speed", type=speed, default=0.0,
                     help="recording pace: 1 = as recorded, 10 = ten times faster (0.0001..1000000), 0 or max = as "
                          "fast as possible (default)")
    out = parser.add_argument_group("where the view goes")
    out.add_argument("--out", type=output_file(into=True), metavar="RRD",
                     help="the .rrd to save (default: next to the recording, or recordings/<session>.rrd; a folder, "
                          "DIR/: that name in it)")
    add_force(out, "an existing .rrd")
    out.add_argument("--no-save", action="store_true", help="do not save an .rrd (needs --serve or --spawn)")
    out.add_argument("--serve", action="store_true",
                     help="serve rerun's web viewer (page and data on 127.0.0.1 only; see docs/view.md)")
    out.add_argument("--grpc-port", type=port_or_any, default=DEFAULT_GRPC_PORT, help="rerun data port for --serve/--spawn")
    out.add_argument("--web-port", type=port_or_any, default=DEFAULT_WEB_PORT, help="web viewer page port for --serve")
    out.add_argument("--spawn", action="store_true", help="open rerun's native viewer (needs a display)")
    out.add_argument("--exit-when-done", action="store_true",
                     help="with --serve: exit when the source ends instead of serving until Ctrl-C")
    out.add_argument("--q-interval", type=float_at_least(0), default=0.25, metavar="S",
                     help="log the Q-table at most every S seconds of session time (default 0.25)")
    out.add_argument("--draw-interval", type=float_at_least(0), default=None, metavar="S",
                     help="draw the board, suggestion and Q-table at most every S seconds (wall clock); every "
                          "event's line and every curve point is kept (default: 0.1 live, 0 = every event "
                          "for a recording)")
    out.add_argument("--nice", type=int_at_least(0), default=10, metavar="N",
                     help="live: lower the view's drawing thread by N nice levels (to 19 at most), so the session it "
                          "watches gets the CPU first; the bus's receive threads keep their priority")
    out.add_argument("--rerun-analytics", action="store_true",
                     help="leave rerun's usage analytics to your rerun settings (default: off for viewers started here)")
    add_bus_arguments(parser)


def _default_rrd(args: argparse.Namespace) -> Path:
    if args.recording:
        return args.recording.with_suffix(".rrd")
    return Path("recordings") / f"{args.session}.rrd"


def run(args: argparse.Namespace) -> int:
    if not args.recording and not args.session:
        raise OptionError("give --session ID (live) or --recording REC", "what to view")
    live, lost, held, events = False, "", None, None
    if args.recording:
        # a file holding no session is refused before rerun loads; read whole, not drawn as it is read: what it lost
        # is known at its end, and decides the .rrd's name before anything is drawn (then drawn from this one read:
        # a second could differ, a recover beside it); its events alone kept, not its records and their bytes
        held, events = session_events(args.recording)
        left_journals("view", [args.recording])  # a cut one's journal beside it holds more: said before it is drawn
        live = held.live or is_live(args.recording)  # its recorder still writes it: what it holds is a part
        # a damaged file that lost events in its middle draws a part too (as rebuild refuses to pass it off as whole;
        # a new user's trial: saved as d.rrd, the whole name, and -q hid the damage)
        # (messages that do not decode are events lost too: reader.EventLog.lost)
        # and so does a cut file (its session's later events are not in it), as a damaged one does: one rule for
        # both (a hostile user's trial: a cut file's view was saved under the complete name, a damaged one's as
        # .partial.rrd); a file its recorder still writes is `live`, said so
        lost = held.lost or ("" if live else held.missing)
        if not lost and not live and not any(type(e).__name__ == "SessionEnded" for e in events):
            # closed whole by a recorder stopped before the session's end (SIGTERM; no SessionEnded): the rest of the
            # session is in no file, as a cut one's; rebuild says PARTIAL, the view was saved under the whole name
            # with 0 notes (trial34 B)
            stopped = held.metadata.get("pairplay.recorder.end", {}).get("stopped_by", "")
            lost = ("closed before its session's end (no SessionEnded recorded"
                    + (f"; its recorder was stopped: {stopped})" if stopped else ")"))
        if args.session:  # before rerun loads and anything is drawn
            if not any(e.session == args.session for e in events):
                raise InputError(f"holds no events of session {args.session}; nothing saved", args.recording)
    if args.no_save and not (args.serve or args.spawn):
        raise OptionError("--no-save leaves no output; add --serve or --spawn", "--no-save")
    rrd = None if args.no_save else (file_in(args.out, _default_rrd(args).name) or _default_rrd(args))
    # a summary of the file it wrote: -q leaves it out; where to watch the view (--serve, --spawn) is a result
    # -q keeps (it was silenced with the summary: view was one of cli/main.py QUIET_SUMMARIES)
    # a result line, its path's control characters escaped (errors.escaped: a newline split it in two)
    say = (lambda line: print(escaped(line))) if not getattr(args, "quiet", False) else (lambda *_, **__: None)
    if rrd is not None:
        # before any work: an existing .rrd stays unless --force, and the recording viewed always
        hold(rrd, "view")  # one writer per output (pairplay/outputs.py)
        check_output(rrd, args.force, inputs=[args.recording] if args.recording else [])
    from pairplay.replay.copies import Copies
    copies = Copies("view", [args.recording] if args.recording else [])  # a study's recording drawn elsewhere: a
    if rrd is not None:  # copy of its participant's data their deletion must know (replay/copies.py)
        copies.check([rrd])
    try:
        with output_path(rrd, args.force) if rrd is not None else contextlib.nullcontext() as tmp:
            done = _view(args, tmp, held, events)
            # never under the name of a complete view (module rule), nor one of a live recording: it was saved
            # as s1.rrd, a part of the session passed off as the whole (a new user's trial)
            if (done.partial or live or lost or done.missed) and rrd is not None:
                raise KeptPartial(keep_partial(tmp, rrd, args.force))
    except KeptPartial as kept:
        try:
            copies.journal([kept.path])
        except KeyboardInterrupt:  # its study folder was busy as the signal stopped the view: the wait ended at once
            # (pairplay/folderlock.py), and a copy of a participant's data that their deletion would not know is
            # never kept (replay/copies.py)
            kept.path.unlink(missing_ok=True)
            print(f"pairplay view: interrupted ({signals.said(done.why)}) after {_counts(done)}, before the source ended; nothing "
                  "saved: its study folder is busy (another pairplay writes it), and the partial view, a copy of "
                  "its participant's data, could not be journaled there", file=sys.stderr)
            return 0
        if not done.partial and lost:  # events lost in the file: what is left, drawn, under a name that says so
            # (a whole file recovered from one that lost parts: `lost` says what, reader.EventLog.source_lost)
            said = f"is damaged ({lost})" if held.damaged else f"was {lost}"
            say(f"saved {kept.path}: {_counts(done)}; partial")
            warn("view", f"{args.recording} {said}; the view is partial ({kept.path})")  # -q or not (cli/main.py)
            return 0
        if not done.partial and done.missed:  # a live session that lost events before the view got them: said
            # (each source's loss is a WARNING on stderr as it is noted, -q or not: sources.SequenceGaps)
            say(f"saved {kept.path}: {_counts(done)}; partial: {missed_text(done.missed)}")
            return 0
        if not done.partial:  # a live recording, drawn as far as it goes: a result, said on stdout
            say(f"saved {kept.path}: {_counts(done)}; partial: {args.recording} {LIVE}, view it again once "
                  "its session has ended")
            return 0
        print(escaped(f"pairplay view: interrupted ({signals.said(done.why)}) after {_counts(done)}, before the source "
                      f"ended; the partial view is in {kept.path}"), file=sys.stderr)
        return 0
    except NothingDrawn as stopped:  # a signal before the first event: nothing to save (exit 128 + signal)
        print(f"pairplay view: interrupted ({signals.said(str(stopped))}) before any event was drawn; nothing saved", file=sys.stderr)
        return 0
    except RrdWriteFailed as err:  # the temporary .rrd is gone (output_path); nothing saved
        raise OutputError(f"writing the .rrd failed ({err}); nothing saved", rrd or "the view's output") from None
    if rrd is not None and not done.partial:
        copies.journal([rrd])
    if done.partial:
        print(f"pairplay view: interrupted ({signals.said(done.why)}) after {_counts(done)}, before the source ended; nothing saved",
              file=sys.stderr)
    else:
        say(f"saved {rrd}: {_counts(done)}" if rrd is not None else
              f"viewed {_counts(done)}{f'; partial: {args.recording} {LIVE}' if live else ''}"
              f"{f'; partial: {missed_text(done.missed)}' if done.missed else ''}")
        if held is not None and held.loss_free:  # a damage that lost no event: drawn whole, the damage said as every
            warn("view", f"{args.recording}: {held.loss_free}")  # verb says it (reader.EventLog.loss_free), on stderr
    return 0


def missed_text(n: int) -> str:
    """What a live view that lost `n` events says (their notes in the view name each source and seq)."""
    return (f"{counted(n, 'event')} of the session never reached the view (published before it joined, with "
            "no recorder's log to catch up from, or dropped); see its notes")


def _counts(done: "Viewed") -> str:
    return f"{counted(done.events, 'event')}, {counted(done.notes, 'note')}, Q-table logged {counted(done.q_logged, 'time')}"


class NothingDrawn(Exception):
    """A signal stopped the view before its first event (the signal's name): the .rrd is discarded."""


class KeptPartial(Exception):
    """A signal stopped the view before its source ended: its .rrd was kept as `path` (keep_partial)."""

    def __init__(self, path: Path):
        super().__init__(str(path))
        self.path = path


@dataclass
class Viewed:
    """What `_view` drew: counts, and whether a signal (`why`) stopped it before its source ended."""

    events: int
    notes: int
    q_logged: int
    partial: bool = False
    why: str = ""
    missed: int = 0  # a live session's events the view never got (sources.SequenceGaps): a part, not the whole


def partial_name(rrd: Path, n: int = 1) -> Path:
    """`<stem>.partial.rrd` beside `rrd`, `<stem>.partial.<n>.rrd` for n > 1."""
    return rrd.with_name(f"{rrd.stem}.partial{'' if n == 1 else f'.{n}'}{rrd.suffix or '.rrd'}")


def keep_partial(tmp: Path, rrd: Path, force: bool) -> Path:
    """Give the finished temporary .rrd of an interrupted view its partial name (module rule):
    `--force` replaces `<stem>.partial.rrd`; without it an existing one stays and the next free
    `<stem>.partial.<n>.rrd` is taken (a hard link: a file that appears meanwhile is not replaced)."""
    if force:
        os.replace(tmp, partial_name(rrd))
        return partial_name(rrd)
    for n in itertools.count(1):
        try:
            os.link(tmp, partial_name(rrd, n))
        except FileExistsError:
            continue
        except OSError as err:  # a file system without hard links
            if err.errno not in NO_HARD_LINKS:
                raise
            if partial_name(rrd, n).exists():
                continue
            os.replace(tmp, partial_name(rrd, n))
        return partial_name(rrd, n)
    raise AssertionError("unreachable")


def _view(args: argparse.Namespace, tmp_rrd: Path | None, held=None, events=None) -> Viewed:
    """Draw into the temporary .rrd (renamed by the caller when this returns); `held`, `events`: the recording as
    `run` read and checked it (check.session_events), drawn so, never read a second time."""
    from pairplay.services.bus import open_bus, options_from_args, shutdown_wait, stop_on_signals
    from pairplay.services.view.drive import drive, lowered_priority
    from pairplay.services.view.output import ViewOutput, finish, open_stream
    from pairplay.services.view.rerun_logger import RerunView
    from pairplay.services.view.sources import LiveSource, recording_items

    out = ViewOutput(rrd=tmp_rrd, serve=args.serve, spawn=args.spawn, grpc_port=args.grpc_port,
                     web_port=args.web_port, rerun_analytics=args.rerun_analytics)
    try:
        rec, where = open_stream(out, recording_name=args.session or args.recording.stem)
    except (RuntimeError, ValueError) as err:  # a viewer that cannot start
        if isinstance(err, UserError):
            raise
        raise OptionError(folded(err), "--spawn" if args.spawn else "the view's output") from None
    for line in where:  # where to watch it: a result of --serve/--spawn, said at once
        print(escaped(line), flush=True)
    stop = threading.Event()
    saved_handlers = {sig: signal.getsignal(sig) for sig in signals.SIGNALS}
    stop_on_signals(stop)
    live = not args.recording
    view = RerunView(rec, q_interval_s=args.q_interval,
                     draw_interval_s=args.draw_interval if args.draw_interval is not None else (0.1 if live else 0.0))
    try:
        if args.recording:
            log.info("drawing %s%s; Ctrl-C to stop", args.recording, f" at {args.speed:g}x" if args.speed else "")
            summary = drive(view, recording_items(args.recording, speed=args.speed, session=args.session, stop=stop,
                                                   log=held, events=events),
                            stop=stop, echo=_echo)
            if summary.events == 0 and stop.is_set():
                raise NothingDrawn(stop.why)
            if summary.events == 0:
                which = f"of session {args.session}" if args.session else "to view"
                raise InputError(f"holds no events {which}; nothing saved", args.recording)
        else:
            with open_bus(options_from_args(args), stop=stop) as bus:
                source = LiveSource(bus, args.session, stop=stop)
                log.info("listening to session %s; Ctrl-C to stop", args.session)
                with lowered_priority(args.nice):  # after the bus's threads started: they keep theirs
                    summary = drive(view, source.items(stop), stop=stop, echo=_echo)
            if summary.events == 0 and stop.is_set():
                raise NothingDrawn(stop.why)
            if summary.events == 0:
                raise InputError("no event of this session arrived; nothing saved", f"--session {args.session}")
        viewed = Viewed(summary.events, summary.notes, summary.q_logged, partial=summary.stopped,
                        why=stop.why if summary.stopped else "", missed=0 if args.recording else source.gaps.missed)
        if args.serve and not args.exit_when_done and not stop.is_set():
            log.info("%d events drawn; still serving; Ctrl-C to stop", summary.events)
            while not stop.wait(0.5):
                pass
    finally:
        try:
            finish(rec, shutdown_wait(stop, 1e9, reserve=0.2))  # stopped: the .rrd's footer within the deadline
        except RuntimeError as err:
            raise RrdWriteFailed(folded(err)) from None  # rerun's words: maybe lines
        for sig, handler in saved_handlers.items():  # run() may be called in-process (tests, tools)
            signal.signal(sig, handler)
    return viewed


def _echo(note: str, level: int) -> None:
    """What the view noticed, on stderr through logging: a loss or a refusal is a WARNING, the rest INFO."""
    log.log(level, "%s", note)

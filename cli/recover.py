"""`pairplay recover REC`: complete a recording a crash cut short (replay/recover.py).

Rule: writes REC's readable records into a complete, indexed file (default
<stem>.recovered.mcap beside it, or -o), and what the recorder's journal beside
it (REC.journal, replay/wal.py) holds that REC lacks, through the live checks
(services/walmerge.py), saying how many it took; the original is never modified, an
existing output is replaced only with --force, and the output appears only
when complete. The line says how many messages the damage lost and where (each
lost part, and the count its Message Indexes give: "18 messages lost (chunk 7
(bytes ...): its 18 messages)", or the summary's Statistics less the messages read
when the lost bytes do not say; "not known" when neither does, "no
message lost" for an index or a summary) and, for a recovered file recovered
again, the earlier losses it carries over (replay/recover.py). Exit 0 when the output is complete, 2 (one line on stderr,
nothing written) when REC is missing, empty or not MCAP (a file of nothing
with its journal beside it, as a recorder killed before its first flush leaves
it, is completed from the journal), holds no session, cut, damaged or whole, and its
journal adds none (only MCAP's magic or header, another program's MCAP, no SessionStarted:
said in the reader's words, reader.EventLog.no_session, as every verb says it), or the output it would write exists. A complete file (whole,
as its recorder finished it) is not copied: the line says it is complete and
what its journal beside it, if any, holds (`nothing more: all N of its records
are in the file`, or the N events it adds, then written to the output as for a
cut file); with nothing recovered nothing is written (exit 0), and an existing output (an
older version's copy) is neither refused nor touched. A journal that
holds nothing more is stale: recover never removes a user's file unasked, it
names `--discard-journal`, which removes such a journal (and only such a one:
refused, nothing changed, when the journal holds something the file lacks or
cannot be read, or when the file is not complete).
A cut REC's journal is kept too, after its events went into the output, and the line says so: it is the
write-ahead log of what REC lacks (services/recorder.py), REC's only other half; removed, REC alone would
recover to less, and the output may be written elsewhere (-o) or lost. Recover never changes its input:
the two are removed by hand once the output is kept (a new user's trial found the journal left, unsaid).
A journal beside a complete REC that is another recording's of the same session id (replay/recover.py
`NotItsJournal`: a cut `session --force` over REC left it, and REC was given its name back) is named as not
REC's, and nothing is written (exit 0): recover had taken it, refused its records and written a copy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pairplay.cli.args import add_force, file_in, output_file
from pairplay.errors import OptionError, command_word, escaped
from pairplay.numbers import counted



def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="REC")
    # --out as every other verb names it (options are given whole: `--out` had worked as the beginning of --output)
    p.add_argument("-o", "--out", "--output", dest="output", type=output_file(into=True),
                   help="output file (default <stem>.recovered.mcap beside REC; a folder: that name in it)")
    add_force(p, "an existing output file")
    p.add_argument("--discard-journal", action="store_true",
                   help="remove the journal beside a complete REC when it holds nothing REC lacks (a stale one)")


def _continued(recording) -> None:
    """Said once recover has done its work (a refusal stays one line, trial36 R1), as every verb says it
    (replay/recover.py journal_left): a file a restarted recorder continued is a part of a session whole beside it
    (trial35 N1: recover wrote a third, partial copy and said nothing of S.1.mcap)."""
    from pairplay.replay.continued import continued_in
    later = continued_in(recording)
    if later is not None:
        from pairplay.cli.main import warn
        warn("recover", f"{recording}: a restarted recorder continued it in {later.name} beside it, which holds "
                        "the whole session from this file's events on: give that to the verbs; this recovers the "
                        "earlier part alone")


def run(args: argparse.Namespace) -> int:
    from pairplay.livelock import LIVE, is_live
    from pairplay.replay.recover import default_output, recover
    from pairplay.replay.wal import wal_path
    from pairplay.services.walmerge import admit

    for live in (args.recording, wal_path(args.recording)):
        if is_live(live):  # not cut: still being written (pairplay/livelock.py); its journal is not stale either
            raise OptionError(f"{LIVE}: recover it once its session has stopped; nothing written", live)

    args.output = file_in(args.output, default_output(Path(args.recording)).name)  # `-o out/`: into out/
    if args.discard_journal:  # decided before anything is written: only a stale journal is removed
        from pairplay.replay.copies import Copies
        # removing it writes the study folder it may be in: the folder's lock first (replay/copies.py module rule)
        Copies("recover", [args.recording]).check([wal_path(args.recording)])
        done = recover(args.recording, args.output, force=args.force, admit=admit, write=False)
        if not done.complete:
            raise OptionError("--discard-journal removes only a stale journal beside a complete recording; this "
                              f"one is not complete ({_not_complete(done)}): recover it without the option",
                              args.recording)
        return _complete(args, done)
    from pairplay.outputs import hold
    from pairplay.replay.copies import Copies
    hold(args.output or default_output(Path(args.recording)), "recover")  # one writer per output (pairplay/outputs.py)
    copies = Copies("recover", [args.recording])  # a study's recording copied beyond recordings/: their deletion knows
    copies.check([args.output or default_output(Path(args.recording))])
    done = recover(args.recording, args.output, force=args.force, admit=admit)
    _continued(args.recording)
    if not done.complete:
        copies.journal([done.output])
    if done.complete:
        return _complete(args, done)
    if done.damaged:
        state = f"damaged ({done.reason}); {_lost(done)}; every intact part kept"
    elif done.truncated:
        state = f"cut short ({done.reason})"
    else:
        state = "complete already"
    ended = "" if done.ended else "; the session's end was not recorded (partial session)"
    journal = ""
    if done.journal is not None:
        journal = (f"; {counted(done.from_journal, 'event')} taken from its journal {done.journal.name}"
                   f"{f', {done.journal_refused} of its messages refused (recorded as refusals)' if done.journal_refused else ''}"
                   f"{f' (read up to its torn tail: {done.journal_torn})' if done.journal_torn else ''}"
                   f"; {args.recording} and its journal are kept as they were (the journal recovers it again; remove "
                   "the two once the output is kept)")
    earlier = f"; what its source had lost is carried over ({done.earlier_lost})" if done.earlier_lost else ""
    earlier += f"; {done.gaps}: {NOT_BACK}" if done.gaps else ""
    if done.copies:  # each event once in the copy (a whole file with copies is no complete one: replay/recover.py)
        state += f"; {counted(done.copies, 'identical copy', 'identical copies')} of events not copied"
    if done.schemas_left_out:  # the copy describes its events by pairplay's schemas only (replay/recover.py)
        state += f"; {done.schemas_left_out}"
    print(escaped(f"{args.recording}: {state}; {counted(done.messages, 'message')} kept in {done.output}{earlier}{journal}{ended}"))
    if done.journal_error:  # what it held (up to the last 5 ms before a crash) is not in the output: said, not silent,
        _journal_unreadable(args, done)  # -q or not
    return 0


# what recover says of events missing from a source's seq in a file that lost no part (reader.EventLog.gaps)
NOT_BACK = "no recover gives them back"


def _journal_unreadable(args: argparse.Namespace, done) -> None:
    """The warning of a journal beside REC that could not be read: on stderr, -q or not (cli/main.py `warn`: a
    logged WARNING, which -q drops, hid what a crash may have lost)."""
    from pairplay.cli.main import warn

    warn("recover", f"the journal beside {args.recording} is unreadable, none of its records were used: "
                    f"{done.journal_error}")


def _lost(done) -> str:
    """How many messages the damage lost and where, in words (recover's line said neither: only each part's
    check, "its records are not read"): "18 messages lost (chunk 7 (bytes ...): its 18 messages)"; a count the
    file does not give (unreadable bytes, no summary to count them: replay/recover.py `_lost_count`) is said to be
    not known; "no message lost" (an index, a summary)."""
    if not done.lost:
        return "no message lost"
    where = "; ".join(done.lost)
    if done.lost_messages is None:
        return f"messages lost, how many is not known ({where})"
    return f"{counted(done.lost_messages, 'message')} lost ({where})"


def _not_complete(done) -> str:
    """Why a recording is not complete, in words (for a refused --discard-journal)."""
    if done.damaged:
        return "damaged"
    if done.truncated:
        return "cut short"
    return f"its journal holds {counted(done.from_journal + done.journal_refused, 'record')} it lacks"


def _complete(args: argparse.Namespace, done) -> int:
    """REC is complete and its journal holds nothing more: nothing was written; say so, and what the
    journal holds; remove a stale journal only with --discard-journal (module rule)."""
    from pairplay.replay.wal import wal_path

    journal = wal_path(args.recording)
    # a whole file recovered from a damaged or cut one: its session still lacks what its source lost, said in the
    # reader's words (reader.EventLog.source_lost, source_cut), as every verb says it (a new user's trial: "nothing
    # to recover" of a copy that had lost 229 messages, and no word of the loss)
    # (and the events missing from a source's seq: reader.EventLog.gaps)
    lost = "; ".join(n for n in (done.earlier_lost, done.earlier_cut, done.gaps and f"{done.gaps}: {NOT_BACK}") if n)
    said = f"{args.recording}: complete already ({counted(done.messages, 'message')}"
    said += f"; {lost}" if lost else ""
    said += ")" if done.ended else "; the session's end was not recorded: a partial session)"
    said += "; nothing to recover, nothing written"
    if done.journal_error:  # unreadable: what it holds is unknown, so it is never called stale
        if args.discard_journal:
            raise OptionError(f"--discard-journal: {done.journal_error}; it was not removed", journal)
        print(escaped(f"{said}; the journal beside it is unreadable"))
        _journal_unreadable(args, done)
        return 0
    if done.not_its_journal:  # another recording's journal: none of it is this file's, and it is not stale either
        if args.discard_journal:
            raise OptionError(f"--discard-journal: {done.not_its_journal}; it was not removed", journal)
        print(escaped(f"{said}; {done.not_its_journal}"))
        return 0
    if done.journal is None:
        if args.discard_journal:
            raise OptionError("--discard-journal: there is no journal beside it", args.recording)
        print(escaped(said))
        return 0
    held = f"its journal {journal.name} holds nothing more ({counted(done.journal_present, 'event')}, all in the file)"
    if args.discard_journal:
        journal.unlink()
        print(escaped(f"{said}; {held}: removed (--discard-journal)"))
        return 0
    print(escaped(f"{said}; {held}: it is stale; `pairplay recover {command_word(args.recording)} --discard-journal` removes it"))
    return 0

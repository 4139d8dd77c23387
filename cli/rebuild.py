"""`pairplay rebuild REC...`: fold recordings into policy files and learning curves.

Rule: each recording X.mcap gives X.policy.json and X.curve.csv in --out
(replay/rebuild.py; named by the file, so the outputs of different recordings
never collide: X.mcap and X.recovered.mcap keep theirs apart; the curve's
`damaged` column marks the rounds a damaged file lost events of), and, unless
--no-plot, one figure of every recording's picks per round (learning curves;
18 picks is perfect play). Before anything is written: every REC must be an
MCAP file, none given twice, no two giving the same output names, and no
output may exist unless --force, no session may be in two RECs (X.mcap and the
X.recovered.mcap `recover` writes beside it: two policies of one learning;
replay/onesession.py), and every REC must hold a session (a
SessionStarted: replay/check.py `read_session`; a stub left by an old
version's failed start, another program's MCAP) with a round recorded whole
(`no_whole_round`: a file cut, or a session stopped, before round 1 ended gave
a policy of 0 rounds, exit 0; with --partial, such a file of a batch is left out,
said, and the others rebuilt: `rebuilt_each`), and, unless --partial, none may have lost events
in its middle (`Rebuilt.lost`: a damaged part, or a recover of a damaged file;
its policy lacks updates the learner made: it was exit 0, flagged, and a
1,500-character damage line printed twice) (one line, exit 2, nothing
written: the others are not rebuilt either, so a rerun after removing it
writes them all). Writing is all or nothing: every output is written into a
temporary folder beside --out and moved in only when all are complete, a signal
waiting while they are (pairplay/outputs.py `output_folder`, `among_others`:
the files already in --out stay), so a full disk or a Ctrl-C part way leaves
--out as it was (with --force: the earlier policies, never half old and half
new) and no folder this run made. --out may hold other files: rebuild lists the
files it wrote there in its manifest (`.pairplay-rebuild.manifest`), and `--force`
removes the ones an earlier rebuild wrote that this one does not write again
(`rebuild A B C --out D`, then `rebuild A --out D --force`: B's and C's policies
and curves stayed beside A's new ones, one folder of two runs); every other
file stays. The result lines are printed once everything is written
(cli/interrupts.py `work_done`: a signal after that is reported, nothing undone).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pairplay.cli.args import add_force, output_folder
from pairplay.core.geometry import PERFECT_PICKS, PICKS_UNIT
from pairplay.errors import escaped
from pairplay.numbers import counted
from pairplay.outputs import manifest_name


FIGURE = "learning-curves.png"
# what rebuild writes in --out (pairplay/outputs.py `owned`); among a user's files there, so its manifest says
# which of them a run wrote: `--force` removes those an earlier run wrote that this one does not write again
REBUILD_OUTPUTS = ("*.policy.json", "*.curve.csv", FIGURE)
MANIFEST = manifest_name("rebuild")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recordings", nargs="+", metavar="REC", help="MCAP recordings of sessions")
    p.add_argument("--out", type=output_folder, default="rebuilt", help="output folder (default rebuilt/)")
    p.add_argument("--no-plot", action="store_true", help="skip the learning-curve figure")
    p.add_argument("--partial", action="store_true",
                   help="also rebuild a recording that lost events in its middle (a damaged file, or one recovered "
                        "from one), exit 0: its policy lacks the lost updates and is flagged partial (without it: "
                        "refused, exit 2, nothing written); and leave out, with a warning, a recording of a batch "
                        "that holds no whole round (without it: the batch is refused)")
    add_force(p, "existing policy files, curves and the figure in --out")


def run(args: argparse.Namespace) -> int:
    from pairplay.cli.interrupts import work_done
    from pairplay.errors import InputError, OutputError
    from pairplay.outputs import check_folder, check_outputs, check_theirs, hold, output_folder
    from pairplay.replay.check import check_recording
    from pairplay.replay.rebuild import output_paths

    hold(args.out, "rebuild")  # one writer per output folder (pairplay/outputs.py): a second is refused
    out = check_folder(args.out)
    check_theirs(out, REBUILD_OUTPUTS, MANIFEST)  # another verb's file there is not ours to replace: said before the work
    from pairplay.replay.copies import Copies
    copies = Copies("rebuild", args.recordings)  # a study's recording rebuilt: a copy their deletion must know
    copies.check([out])
    seen: dict[Path, str] = {}
    for rec in args.recordings:
        key = check_recording(rec).resolve()
        if key in seen:
            raise InputError(f"given twice (also as {seen[key]})", rec)
        seen[key] = rec
    done, empty = rebuilt_each(args)  # one holding no session: refused, nothing written
    for rebuilt in done:
        if rebuilt.lost and not args.partial:  # it was exit 0 with a PARTIAL policy and a 1,500-character line, twice
            raise InputError(f"{rebuilt.lost}: its policy would lack the updates lost with it", rebuilt.source,
                             fix="--partial writes it anyway, flagged partial", option="--partial")
    planned: dict[Path, tuple[Path, str]] = {}  # resolved -> (the path as the user will read it, its source)
    for rebuilt in done:
        for path in output_paths(rebuilt, out):
            if path.resolve() in planned:
                raise OutputError(f"{planned[path.resolve()][1]} and {rebuilt.source} would write the same output; "
                                  "rename one", path)
            planned[path.resolve()] = (path, rebuilt.source)
    from pairplay.replay.onesession import check_once
    check_once((rebuilt.source, rebuilt.started) for rebuilt in done)  # X.mcap and X.recovered.mcap: one session
    figure = out / FIGURE
    # named as given: "exists (/tmp/.../rq/x.policy.json)" for `--out rq` (the resolved key)
    outputs = [path for path, _ in planned.values()] + ([figure] if done and not args.no_plot else [])
    check_outputs(outputs, args.force, inputs=args.recordings)
    with output_folder(out, args.force, owned=REBUILD_OUTPUTS, among_others=True, manifest=MANIFEST) as staged:
        lines = write_all(done, staged, out, args)
    # each recording's policy and curve are its participant's; the figure is everyone's (one call: a line that cannot
    # be written removes every output still waiting for its line, replay/copies.py journal_each)
    copies.journal_each([(output_paths(rebuilt, out), [rebuilt.source]) for rebuilt in done]
                        + ([([figure], None)] if done and not args.no_plot else []))
    work_done()  # everything is written: a signal from now on is reported, and undoes nothing
    print("\n".join(escaped(line) for line in lines))  # a path's newline would split its line (errors.escaped)
    from pairplay.cli.main import left_journals, warn

    for err in empty:  # left out with --partial (`rebuilt_each`): said first, in the refusal's words
        warn("rebuild", f"{err.where}: left out (--partial): {err.what}")
    for rebuilt in done:  # warnings about the result, on stderr, -q or not (cli/main.py: -q hid them with the listing)
        if rebuilt.partial:  # the damage (the note) is said here, once, short (reader.EventLog.brief)
            warn("rebuild", f"{rebuilt.source}: PARTIAL session: {rebuilt.partial}")
        if rebuilt.damage_read:
            warn("rebuild", f"{rebuilt.source}: {rebuilt.damage_read}")
    left_journals("rebuild", [rebuilt.source for rebuilt in done])
    return 0


def rebuilt_each(args: argparse.Namespace) -> tuple[list, list]:
    """Each REC rebuilt (replay/rebuild.py), and the refusals of those that hold no whole round (`NoWholeRound`)
    left out with --partial: one such file in a batch (`rebuild recordings/*.mcap`: a session interrupted at
    once among them) refused the whole batch, with or without --partial, and its line did not say what to do
    (trial30 #3). Without --partial it still refuses the batch (nothing written), its line saying to leave it
    out or give --partial; with it, it is left out and said, the others rebuilt; a batch of none but such
    files is refused (nothing to rebuild)."""
    from pairplay.replay.rebuild import NoWholeRound, rebuild_recording

    done, empty = [], []
    for rec in args.recordings:
        try:
            done.append(rebuild_recording(rec))
        except NoWholeRound as err:
            if len(args.recordings) == 1:
                raise
            if not args.partial:
                raise NoWholeRound(err.what, err.where, option="--partial",
                                   fix="leave it out, or --partial rebuilds the others without it") from None
            empty.append(err)
    if not done:
        raise NoWholeRound(f"none of the {counted(len(args.recordings), 'recording')} holds a whole round; the first "
                           f"{empty[0].what}", empty[0].where)
    return done, empty


def write_all(done, staged: Path, out: Path, args: argparse.Namespace) -> list[str]:
    """Write each rebuilt recording's outputs and the figure into `staged` (output_folder's); the
    lines saying what was written, by the names they will have in `out` (printed by the caller only
    once all of it is moved in)."""
    from pairplay.replay.rebuild import write_outputs
    lines = []
    for rebuilt in done:
        paths = write_outputs(rebuilt, staged)
        f = rebuilt.fold
        picks = f.picks_per_round()
        mean = f"{sum(picks) / len(picks):.1f}" if picks else "-"
        updates = f"{f.counts.get('LSPIUpdated', 0)} LSPI samples" if f.lspi is not None else \
            f"{f.counts.get('QUpdated', 0)} Q updates"
        lines.append(f"{rebuilt.source}: {counted(f.events, 'event')}, {counted(len(picks), 'round')}, mean {mean} {PICKS_UNIT}, "
                     f"{updates}"
                     f"{'; %d q_before mismatches' % f.q_mismatches if f.q_mismatches else ''}")
        lines.append("  " + ", ".join(str(out / p.name) for p in paths))
    if done and not args.no_plot:
        plot_curves(done, staged / FIGURE)
        lines.append(f"  {out / FIGURE}")
    return lines


def curve_points(fold) -> tuple[list[int], list[int]]:
    """A recording's line in the figure: each whole round's picks at its own round, counted from 1 (a round whose
    end a damaged file lost has no point, and the rounds after it stay in their places: drawn at 1, 2, ... in
    order, they moved one to the left)."""
    rounds = fold.whole_rounds()
    return [r + 1 for r in rounds], fold.picks_per_round()


def plot_curves(rebuilt, path: Path, force: bool = False) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pairplay.outputs import output_path

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in rebuilt:
        ax.plot(*curve_points(r.fold), label=Path(r.source).name, lw=1)
    ax.axhline(PERFECT_PICKS, color="grey", ls=":", lw=1, label=f"perfect play ({PERFECT_PICKS} picks)")
    ax.set_xlabel("round")
    ax.set_ylabel(PICKS_UNIT)
    ax.set_title("learning curves rebuilt from recordings")
    if len(rebuilt) <= 10:
        ax.legend(fontsize=7)
    fig.tight_layout()
    with output_path(path, force) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path

"""`pairplay rebuild REC...`: fold recordings into policy files and learning curves.

Rule: each recording X.mcap gives X.policy.json and X.curve.csv in --out
(replay/rebuild.py; named by the file, so the outputs of different recordings
never collide: X.mcap and X.recovered.mcap keep theirs apart), and, unless
--no-plot, one figure of every recording's picks per round (learning curves;
18 picks is perfect play). Before anything is written: every REC must be an
MCAP file, none given twice, no two giving the same output names, and no
output may exist unless --force (one line, exit 2, nothing written). An MCAP
recording that holds no session (a stub left by a failed start) is reported
on stderr and skipped, the others are still rebuilt, and the exit status is 1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pairplay.cli.args import add_force
from pairplay.core.geometry import PERFECT_PICKS, PICKS_UNIT


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recordings", nargs="+", metavar="REC", help="MCAP recordings of sessions")
    p.add_argument("--out", default="rebuilt", help="output folder (default rebuilt/)")
    p.add_argument("--no-plot", action="store_true", help="skip the learning-curve figure")
    add_force(p, "existing policy files, curves and the figure in --out")


def run(args: argparse.Namespace) -> int:
    from pairplay.errors import InputError, OutputError
    from pairplay.outputs import check_folder, check_outputs
    from pairplay.replay.check import check_recording
    from pairplay.replay.rebuild import RebuildError, output_paths, rebuild_recording, write_outputs

    out = check_folder(args.out)
    seen: dict[Path, str] = {}
    for rec in args.recordings:
        key = check_recording(rec).resolve()
        if key in seen:
            raise InputError(f"given twice (also as {seen[key]})", rec)
        seen[key] = rec
    done, failed = [], 0
    for rec in args.recordings:
        try:
            done.append(rebuild_recording(rec))
        except RebuildError as err:
            print(f"pairplay rebuild: skipped: {err.line()}", file=sys.stderr)
            failed += 1
    planned: dict[Path, str] = {}
    for rebuilt in done:
        for path in output_paths(rebuilt, out):
            if path.resolve() in planned:
                raise OutputError(f"{planned[path.resolve()]} and {rebuilt.source} would write the same output; "
                                  "rename one", path)
            planned[path.resolve()] = rebuilt.source
    figure = out / "learning-curves.png"
    check_outputs(list(planned) + ([figure] if done and not args.no_plot else []), args.force)
    for rebuilt in done:
        paths = write_outputs(rebuilt, out, args.force)
        f = rebuilt.fold
        picks = f.picks_per_round()
        mean = f"{sum(picks) / len(picks):.1f}" if picks else "-"
        updates = f"{f.counts.get('LSPIUpdated', 0)} LSPI samples" if f.lspi is not None else \
            f"{f.counts.get('QUpdated', 0)} Q updates"
        print(f"{rebuilt.source}: {f.events} events, {len(picks)} rounds, mean {mean} {PICKS_UNIT}, "
              f"{updates}"
              f"{'; ' + rebuilt.note if rebuilt.note else ''}"
              f"{'; %d q_before mismatches' % f.q_mismatches if f.q_mismatches else ''}")
        if rebuilt.partial:
            print(f"  PARTIAL session: {rebuilt.partial}")
        print("  " + ", ".join(str(p) for p in paths))
    if done and not args.no_plot:
        print(f"  {plot_curves(done, figure, args.force)}")
    return 1 if failed else 0


def plot_curves(rebuilt, path: Path, force: bool = False) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pairplay.outputs import output_path

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in rebuilt:
        picks = r.fold.picks_per_round()
        ax.plot(range(1, len(picks) + 1), picks, label=Path(r.source).name, lw=1)
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

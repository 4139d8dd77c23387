"""`pairplay rebuild REC...`: fold recordings into policy files and learning curves.

Rule: each recording gives <session>.policy.json and <session>.curve.csv in
--out (replay/rebuild.py), and, unless --no-plot, one figure of every
recording's turns per round (learning curves; 9 turns is perfect play). A
recording that cannot be rebuilt is reported with the reason and the others
still are; the exit status is 1 if any failed.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recordings", nargs="+", metavar="REC", help="MCAP recordings of sessions")
    p.add_argument("--out", default="rebuilt", help="output directory (default rebuilt/)")
    p.add_argument("--no-plot", action="store_true", help="skip the learning-curve figure")


def run(args: argparse.Namespace) -> int:
    from pairplay.replay.rebuild import RebuildError, rebuild_recording, write_outputs

    done, failed = [], 0
    for rec in args.recordings:
        try:
            rebuilt = rebuild_recording(rec)
        except (RebuildError, OSError) as err:
            print(f"{rec}: cannot rebuild: {err}")
            failed += 1
            continue
        paths = write_outputs(rebuilt, args.out)
        f = rebuilt.fold
        turns = f.turns_per_round()
        updates = f"{f.counts.get('LSPIUpdated', 0)} LSPI samples" if f.lspi is not None else \
            f"{f.counts.get('QUpdated', 0)} Q updates"
        print(f"{rec}: {f.events} events, {len(turns)} rounds, {updates}"
              f"{'; %d q_before mismatches' % f.q_mismatches if f.q_mismatches else ''}")
        if rebuilt.partial:
            print(f"  PARTIAL session: {rebuilt.partial}")
        print("  " + ", ".join(str(p) for p in paths))
        done.append(rebuilt)
    if done and not args.no_plot:
        print(f"  {plot_curves(done, Path(args.out) / 'learning-curves.png')}")
    return 1 if failed else 0


def plot_curves(rebuilt, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for r in rebuilt:
        turns = r.fold.turns_per_round()
        ax.plot(range(1, len(turns) + 1), turns, label=r.config.session, lw=1)
    ax.axhline(9, color="grey", ls=":", lw=1, label="perfect play (9 turns)")
    ax.set_xlabel("round")
    ax.set_ylabel("turns to clear the board")
    ax.set_title("learning curves rebuilt from recordings")
    if len(rebuilt) <= 10:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

"""`pairplay rebuild REC...`: fold recordings into policy files and learning curves.

Rule: each recording X.mcap gives X.policy.json and X.curve.csv in --out
(replay/rebuild.py; named by the file, so the outputs of different recordings
never collide: X.mcap and X.recovered.mcap keep theirs apart), and, unless
--no-plot, one figure of every recording's picks per round (learning curves;
18 picks is perfect play). Before anything is written: every REC must be an
MCAP file, none given twice, no two giving the same output names, and no
output may exist unless --force, and every REC must hold a session (a
SessionStarted: replay/check.py `read_session`; a stub left by an old
version's failed start, another program's MCAP) (one line, exit 2, nothing
written: the others are not rebuilt either, so a rerun after removing it
writes them all). Writing is all or nothing (`all_or_nothing`): a full disk or
Ctrl-C part way removes the outputs this run had made, and the error says so.
"""

from __future__ import annotations

import argparse
import contextlib
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
    from pairplay.replay.rebuild import output_paths, rebuild_recording

    out = check_folder(args.out)
    seen: dict[Path, str] = {}
    for rec in args.recordings:
        key = check_recording(rec).resolve()
        if key in seen:
            raise InputError(f"given twice (also as {seen[key]})", rec)
        seen[key] = rec
    done = [rebuild_recording(rec) for rec in args.recordings]  # one holding no session: refused, nothing written
    planned: dict[Path, str] = {}
    for rebuilt in done:
        for path in output_paths(rebuilt, out):
            if path.resolve() in planned:
                raise OutputError(f"{planned[path.resolve()]} and {rebuilt.source} would write the same output; "
                                  "rename one", path)
            planned[path.resolve()] = rebuilt.source
    figure = out / "learning-curves.png"
    outputs = list(planned) + ([figure] if done and not args.no_plot else [])
    check_outputs(outputs, args.force)
    with all_or_nothing(outputs):
        report(done, out, figure, args)
    return 0


@contextlib.contextmanager
def all_or_nothing(outputs: list[Path]):
    """The outputs are written all, or none of those that did not exist before: an error (a full disk)
    or Ctrl-C part way removes the ones this run had made; an OSError then says so, and names, with
    --force, the files it had already replaced (each complete: pairplay.outputs), which stay."""
    def stamp(p: Path):
        st = p.stat()
        return st.st_ino, st.st_mtime_ns
    before = {p: stamp(p) for p in outputs if p.exists()}
    try:
        yield
    except BaseException as err:
        made = [p for p in outputs if p not in before and p.exists()]
        for p in made:
            p.unlink(missing_ok=True)
        replaced = [str(p) for p in before if p.exists() and stamp(p) != before[p]]
        if isinstance(err, OSError):
            note = f"removed the {len(made)} outputs written before it" if made else "nothing written"
            if replaced:
                note += f"; already replaced (complete, kept): {', '.join(replaced)}"
            raise OSError(err.errno, f"{err.strerror or err}; {note}", err.filename) from err
        raise


def report(done, out: Path, figure: Path, args: argparse.Namespace) -> None:
    """Write each rebuilt recording's outputs and the figure, then say what was written (only once
    all of it is: `all_or_nothing` may remove it)."""
    from pairplay.replay.rebuild import write_outputs
    lines = []
    for rebuilt in done:
        paths = write_outputs(rebuilt, out, args.force)
        f = rebuilt.fold
        picks = f.picks_per_round()
        mean = f"{sum(picks) / len(picks):.1f}" if picks else "-"
        updates = f"{f.counts.get('LSPIUpdated', 0)} LSPI samples" if f.lspi is not None else \
            f"{f.counts.get('QUpdated', 0)} Q updates"
        lines.append(f"{rebuilt.source}: {f.events} events, {len(picks)} rounds, mean {mean} {PICKS_UNIT}, "
                     f"{updates}"
                     f"{'; ' + rebuilt.note if rebuilt.note else ''}"
                     f"{'; %d q_before mismatches' % f.q_mismatches if f.q_mismatches else ''}")
        if rebuilt.partial:
            lines.append(f"  PARTIAL session: {rebuilt.partial}")
        lines.append("  " + ", ".join(str(p) for p in paths))
    if done and not args.no_plot:
        lines.append(f"  {plot_curves(done, figure, args.force)}")
    print("\n".join(lines))


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

"""`pairplay study`: the virtual study of thesis chapter 6, end to end.

Rule: one command, reproducible by seed, writes a report folder:
  policies/<persona>/game-NN.json   one policy file per game (schemas/policy.py)
  curves.csv, curves_summary.csv    picks per round per game; mean/sd/min/max per round
  learning_curves.png               figure 6.4 (memory, focus, impairment)
  evaluation.csv, evaluation.png    user alone vs learned vs oracle, picks per round
  report.md                         the tables and figures, with the run's settings
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pairplay import __version__
from pairplay.core import study
from pairplay.core.personas import PERSONAS, persona
from pairplay.core.policies import to_policy_file
from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.policy import write_policy

from . import plots


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=0, help="study seed (default 0)")
    p.add_argument("--personas", default=",".join(PERSONAS),
                   help="comma-separated persona keys (default: all of appendix A)")
    p.add_argument("--games", type=int, default=10, help="games per persona (thesis: 10)")
    p.add_argument("--rounds", type=int, default=500, help="rounds per game (thesis: 500)")
    p.add_argument("--eval-rounds", type=int, default=200,
                   help="rounds each greedy policy is evaluated with epsilon 0 (default 200)")
    p.add_argument("--out", type=Path, default=Path("out/study"), help="report folder (default out/study)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def _bar(args, total: int, desc: str):
    return tqdm(total=total, desc=desc, unit="round", disable=args.quiet, file=sys.stderr,
                dynamic_ncols=True, leave=False)


def _progress(bar):
    last = [0]

    def update(done: int) -> None:
        bar.update(done - last[0])
        last[0] = done
    return update


def write_curves(out: Path, training: study.Training) -> dict[str, np.ndarray]:
    picks = training.result.picks
    curves: dict[str, list[np.ndarray]] = {}
    with open(out / "curves.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["persona", "game", "round", "picks", "inconsistent"])
        for row, (p, g) in enumerate(zip(training.personas, training.game_index)):
            curves.setdefault(p.key, []).append(picks[row])
            for r, (n, inc) in enumerate(zip(picks[row], training.result.inconsistent[row])):
                w.writerow([p.key, int(g), r, int(n), int(inc)])
    stacked = {k: np.stack(v) for k, v in curves.items()}
    with open(out / "curves_summary.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["persona", "round", "mean", "sd", "min", "max"])
        for key, c in stacked.items():
            for r in range(c.shape[1]):
                col = c[:, r]
                w.writerow([key, r, f"{col.mean():.3f}", f"{col.std():.3f}", int(col.min()), int(col.max())])
    return stacked


def write_policies(out: Path, training: study.Training, args, config: LearnerConfig) -> list[Path]:
    paths = []
    for row, (p, g) in enumerate(zip(training.personas, training.game_index)):
        path = out / "policies" / p.key / f"game-{int(g):02d}.json"
        write_policy(path, to_policy_file(
            training.result.q[row], training.result.counts[row], training.greedy[row],
            algorithm="q-learning", participant=p.key, persona=p, seed=training.seeds[row], game=int(g),
            rounds=args.rounds, config=config, software=f"pairplay {__version__}"))
        paths.append(path)
    return paths


def evaluation_table(cmp: study.Comparison) -> list[list[str]]:
    rows = [["persona", "focus", "user alone", "learned (mean \u00b1 sd)", "oracle", "learned/oracle"]]
    for i, key in enumerate(cmp.persona):
        rows.append([key, str(PERSONAS[key].focus), f"{cmp.alone[i]:.2f}",
                     f"{cmp.learned[i]:.2f} \u00b1 {cmp.learned_spread[i]:.2f}", f"{cmp.oracle[i]:.2f}",
                     f"{cmp.learned[i] / cmp.oracle[i]:.3f}"])
    return rows


def markdown_table(rows: list[list[str]]) -> str:
    head, *body = rows
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in body]
    return "\n".join(lines)


def text_table(rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.rjust(w) if j else c.ljust(w) for j, (c, w) in enumerate(zip(r, widths)))
                     for r in rows)


def run(args) -> int:
    try:
        personas = [persona(k.strip()) for k in args.personas.split(",") if k.strip()]
    except KeyError as exc:
        print(f"pairplay study: {exc.args[0]}", file=sys.stderr)
        return 2
    if args.games < 1 or args.rounds < 1 or args.eval_rounds < 1:
        print("pairplay study: --games, --rounds and --eval-rounds must be at least 1", file=sys.stderr)
        return 2
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    config = LearnerConfig()
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    with _bar(args, len(personas) * args.games * args.rounds, "training") as bar:
        training = study.train(personas, args.games, args.rounds, args.seed, config, progress=_progress(bar))
    timings["training"] = time.perf_counter() - t0

    write_policies(out, training, args, config)
    curves = write_curves(out, training)
    plots.learning_curves(curves, {p.key: p.name for p in personas}, out / "learning_curves.png")

    t0 = time.perf_counter()
    n_eval = 3 * len(personas) * args.games * args.eval_rounds
    with _bar(args, n_eval, "evaluation") as bar:
        cmp = study.compare(personas, training, args.eval_rounds, args.seed, progress=_progress(bar))
    timings["evaluation"] = time.perf_counter() - t0
    table = evaluation_table(cmp)
    with open(out / "evaluation.csv", "w", newline="") as f:
        csv.writer(f).writerows(table)
    plots.comparison_bars(cmp.persona, {"user alone": cmp.alone, "learned": cmp.learned, "oracle": cmp.oracle},
                          out / "evaluation.png", "picks per round (epsilon 0)")

    first50 = {k: c[:, :50].mean() for k, c in curves.items()}
    last50 = {k: c[:, -50:].mean() for k, c in curves.items()}
    report = [
        "# pairplay study report", "",
        f"pairplay {__version__}, seed {args.seed}, {len(personas)} personas x {args.games} games x "
        f"{args.rounds} rounds, Q-learning with the thesis's schedules (epsilon 0.9 - 0.1/50 rounds, "
        f"floor 0.1; alpha 0.5 - 0.05/50 rounds).", "",
        "## Learned policies against the references", "",
        f"Picks per round, each greedy policy played {args.eval_rounds} rounds with epsilon 0; the oracle "
        "and the user alone play the same games (core/oracle.py documents the oracle).", "",
        markdown_table(table), "", "![evaluation](evaluation.png)", "",
        "## Learning curves (figure 6.4)", "",
        markdown_table([["persona", "first 50 rounds", "last 50 rounds"]] +
                       [[k, f"{first50[k]:.2f}", f"{last50[k]:.2f}"] for k in curves]), "",
        "![learning curves](learning_curves.png)", "",
        "## Timings", "",
        markdown_table([["phase", "seconds"]] + [[k, f"{v:.2f}"] for k, v in timings.items()]), "",
    ]
    (out / "report.md").write_text("\n".join(report))

    print(text_table(table))
    print()
    print(f"training: {timings['training']:.2f} s for {len(training.personas)} games x {args.rounds} rounds "
          f"({training.result.turns} lockstep turns); evaluation: {timings['evaluation']:.2f} s")
    print(f"report: {out / 'report.md'}")
    return 0

"""The study report's sections on the thesis's future work (chapter 8).

Rule: one function per section; each takes the result of a `core` experiment,
writes its CSV and figure into the report folder, and returns the section's
markdown lines. Numbers are picks per round (18 = perfect play; lower is
better), mean and standard deviation over the experiment's replicates.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from pairplay.report import plots


def precombination_section(out: Path, exp, names: dict[str, str], oracle: dict[str, float],
                           markdown_table) -> list[str]:
    """Future work 3: a user represented by one random policy, by all its policies, or pre-combined.

    `exp` is a core.precombine.CombinationExperiment; writes precombination.csv and .png."""
    picks = exp.picks  # (strategies, replicates, personas)
    R = picks.shape[1]
    header = ["representation of each user", "mean over personas", *exp.persona, "states settled by Q (Error)"]
    rows = [header]
    for k, strategy in enumerate(exp.strategies):
        overall = picks[k].mean(axis=1)  # (replicates,)
        rows.append([strategy, f"{overall.mean():.2f} \u00b1 {overall.std():.2f}",
                     *[f"{picks[k, :, j].mean():.2f} \u00b1 {picks[k, :, j].std():.2f}" for j in range(len(exp.persona))],
                     f"{exp.errors_resolved[k].mean():.1f}"])
    rows.append(["oracle", f"{np.mean([oracle[p] for p in exp.persona]):.2f}",
                 *[f"{oracle[p]:.2f}" for p in exp.persona], ""])
    with open(out / "precombination.csv", "w", newline="") as f:
        csv.writer(f).writerows(rows)
    plots.grouped_bars_with_spread(
        [names.get(p, p) for p in exp.persona], {s: picks[k] for k, s in enumerate(exp.strategies)},
        [oracle[p] for p in exp.persona], out / "precombination.png",
        f"merge of all personas, picks per round (epsilon 0; mean \u00b1 sd over {R} replicates)")
    base, pre = picks[0].mean(axis=1), picks[2].mean(axis=1)
    diff = pre - base
    verdict = ("better" if diff.mean() < 0 else "worse") if abs(diff.mean()) > diff.std() else "no clearer"
    return [
        "## Per-user pre-combination (future work 3)", "",
        "The thesis represents each user in a merge by one random policy (6.2) and proposes merging each "
        "user's own policies first (chapter 8). Here all personas are merged three ways, on the same "
        f"policies: {R} replicates, each from disjoint games of every persona (2 policies a user when "
        "10 games make 5 replicates, as in the human study's phase 1); each merge plays the same "
        "evaluation games on every persona. Picks per round, lower is better.", "",
        markdown_table(rows), "",
        f"Pre-combined minus one random policy, mean over personas: {diff.mean():+.2f} \u00b1 {diff.std():.2f} "
        f"picks per round over the replicates ({verdict} than the thesis's way). 'All policies' gives "
        "every policy a vote of its own; with one persona clearly lowest in errors per channel it "
        "settles the same parts as pre-combination, and they differ only where errors tie.", "",
        "![pre-combination](precombination.png)", "",
    ]

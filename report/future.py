"""The study report's sections on the thesis's future work (chapter 8).

Rule: each section takes the result of a `core` experiment, writes its CSV and
figure into the report folder, and returns the section's markdown lines.
Numbers are picks per round (18 = perfect play; lower is better), mean and
standard deviation over the experiment's replicates.

How a section joins the study (report/study.py runs `SECTIONS` in order):
a section is a function `section(state: Study, batch) -> finish | None`.
Before the study's evaluations play, it computes what it needs from `state`
(the training, the users, the settings) and queues its evaluation games in
`batch`, the study's single core.study.Evaluations (`batch.add(personas,
policies, rounds, game_index)`, or a core helper that calls it, such as
`core.study.add_on_personas`), keeping the slices `add` returns. It returns
None if it does not apply to these settings (then `not_run_lines` gives its
heading and why, so the report never drops a section without a word), else `finish(state) -> lines`,
which the study calls after the batch has played (`batch.picks[slice]`; the
comparison's `state.oracle` and `state.alone` are set by then): it writes the
section's CSV, hands its figure to `state.figures.draw(name, *plain data)` (a
function of report/plots.py listed in `plots.FIGURES`, drawn in the figure
process) and returns its markdown lines. Sections come after the report's
timings, so the thesis's study above them keeps its pinned bytes; a section
never changes another's numbers (a row of the batch plays the same game
whatever else is queued). Learning games of a section's own (new personas,
other learners) go through one `core.simulate.run_games` call of its own in
the queueing step. Keep a section cheap: `pairplay study` has a 5 s budget
(bench/goals.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pairplay import csvcell
from pairplay.core.precombine import add_combination
from pairplay.numbers import counted


@dataclass
class Study:
    """What a future-work section may read (see the module rule)."""

    args: Any  # report.study.StudySettings
    out: Path  # the report folder being written
    personas: list  # the study's personas (core Persona)
    names: dict[str, str]  # persona key -> display name
    training: Any  # core.study.Training
    users: Any  # core.study.UserSet
    figures: Any  # report.study._Figures: .draw(name, *args)
    markdown_table: Callable[[list[list[str]]], str]
    oracle: dict[str, float] = field(default_factory=dict)  # persona key -> the oracle's picks per round (after play)
    alone: dict[str, float] = field(default_factory=dict)  # persona key -> the user alone's (after play)


PRECOMBINATION_HEADING = "## Per-user pre-combination (future work 3)"
MIN_GAMES = 5  # five disjoint replicates of each persona's games (core/precombine.py)


def applies(state: Study) -> str:
    """Why the future-work sections cannot run with these settings ("" if they can): both merge personas'
    policies from disjoint replicates of their games."""
    games, n = state.args.games, len(state.personas)
    if games >= MIN_GAMES and n >= 2:
        return ""
    return (f"Not run: this section needs at least {MIN_GAMES} games per persona (disjoint replicates of each "
            f"persona's policies) and at least 2 personas to merge; this study has "
            f"{counted(games, 'game')} of {counted(n, 'persona')}.")


def precombination(state: Study, batch):
    """Future work 3 (core/precombine.py): needs 5 disjoint replicates of each persona's games, 2+ personas."""
    if applies(state):
        return None
    pending = add_combination(batch, state.personas, state.training, state.args.seed)

    def finish(played: Study) -> list[str]:
        return precombination_section(played.out, pending(batch), played.names, played.oracle,
                                      played.markdown_table, played.figures.draw)
    return finish


def action_level(state: Study, batch):
    """Future work 1 (core/actionlevel.py): on the same studies as future work 3; its reading personas
    learn in games of their own, the partners' games are the study's."""
    if applies(state):
        return None
    from pairplay.core.actionlevel import add_action_level
    from pairplay.report.future_actions import action_level_section
    a = state.args
    pending = add_action_level(batch, a.seed, a.rounds, state.training, reward_bonus=a.reward_bonus)

    def finish(played: Study) -> list[str]:
        return action_level_section(played.out, pending(), played.markdown_table, played.figures.draw)
    return finish


SECTIONS = (precombination, action_level)


def not_run_lines(state: Study) -> list[str]:
    """The headings of the sections that do not apply to these settings, each with why (a study of one
    persona, or of fewer than 5 games, left them out without a word)."""
    why = applies(state)
    if not why:
        return []
    from pairplay.report.future_actions import ACTION_LEVEL_HEADING
    return [line for heading in (PRECOMBINATION_HEADING, ACTION_LEVEL_HEADING) for line in (heading, "", why, "")]


def precombination_section(out: Path, exp, names: dict[str, str], oracle: dict[str, float],
                           markdown_table, draw=None) -> list[str]:
    """Future work 3: a user represented by one random policy, by all its policies, or pre-combined.

    `exp` is a core.precombine.CombinationExperiment; writes precombination.csv and, through
    `draw` (report/plots.py `draw` by default), precombination.png."""
    if draw is None:
        from pairplay.report.plots import draw
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
        csvcell.writer(f).writerows(rows)
    draw("grouped_bars_with_spread",
         [names.get(p, p) for p in exp.persona], {s: picks[k] for k, s in enumerate(exp.strategies)},
         [float(oracle[p]) for p in exp.persona], out / "precombination.png",
         f"merge of all personas, picks per round (epsilon 0; mean \u00b1 sd over {R} replicates)")
    base, pre = picks[0].mean(axis=1), picks[2].mean(axis=1)
    diff = pre - base
    verdict = ("better" if diff.mean() < 0 else "worse") if abs(diff.mean()) > diff.std() else "no clearer"
    return [
        PRECOMBINATION_HEADING, "",
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

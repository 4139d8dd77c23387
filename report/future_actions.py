"""The study report's section on action-level profiles (thesis chapter 8, future work 1).

Rule: `action_level_section` takes a core.actionlevel.ActionLevelExperiment,
writes action_profiles.csv, action_merges.csv and action_merges.png into the
report folder and returns the section's markdown lines (as report/future.py's
sections). Shares are of the 23 compared states; picks are per round (18 =
perfect play; lower is better), mean and standard deviation over replicates.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pairplay import csvcell
from pairplay.core.actions import ACTION_NAMES
from pairplay.core.geometry import PERFECT_PICKS, STATE_NAMES
from pairplay.core.personas import READING_PERSONAS
from pairplay.report import plots
from pairplay.numbers import counted


ACTION_LEVEL_HEADING = "## Action-level profiles (future work 1)"


def _pct(x: float) -> str:
    return f"{100 * x:.0f}"


def _spread(x: np.ndarray, scale: float = 1.0, digits: int = 2) -> str:
    return f"{scale * x.mean():.{digits}f} \u00b1 {scale * x.std():.{digits}f}"


def profile_rows(exp) -> list[list[str]]:
    """Per persona: algorithm 3 beside the action-level information, over all its policies and per replicate."""
    rows = [["persona", "reads as one whole", "algorithm 3: speech % / head %", "action level: speech % / head %",
             "synonym states (counted by algorithm 3 only)", "wholes found (state: action)",
             f"{counted(exp.replicate_info.shape[1], 'replicate')} of 2 policies: algorithm 3 -> action level, speech % / head %"]]
    for i, key in enumerate(exp.persona):
        prof = exp.profiles[key]
        reads = ", ".join(READING_PERSONAS[key].reads) if key in READING_PERSONAS else ""
        rep = exp.replicate_info[i]  # (replicates, 4)
        wholes = "; ".join(f"{STATE_NAMES[s]}: {ACTION_NAMES[a]}" for s, a in prof.wholes[:3])
        wholes = f"{len(prof.wholes)}" + (f" ({wholes}{'; ...' if len(prof.wholes) > 3 else ''})" if wholes else "")
        rows.append([key, reads or "- (the thesis's reading)",
                     f"{_pct(prof.algorithm3.speech)} / {_pct(prof.algorithm3.head)}",
                     f"{_pct(prof.info.speech)} / {_pct(prof.info.head)}",
                     ", ".join(STATE_NAMES[s] for s in prof.synonym_states) or "-", wholes,
                     f"{_spread(rep[:, 0], 100, 0)} / {_spread(rep[:, 1], 100, 0)} -> "
                     f"{_spread(rep[:, 2], 100, 0)} / {_spread(rep[:, 3], 100, 0)}"])
    return rows


def merge_rows(exp) -> list[list[str]]:
    """Per merge and member: picks per round of the merged policy by each strategy, and the change."""
    rows = [["merge", "played by", *exp.strategies, "change (wholes kept - algorithm 3 + 4)",
             "states the wholes step changed"]]
    for c, (j, key) in enumerate(exp.members):
        picks = exp.picks[:, :, c]  # (strategies, replicates)
        rows.append(["+".join(exp.merges[j]), key, *[_spread(p) for p in picks], _spread(picks[-1] - picks[0]),
                     _spread(exp.replaced[:, j].astype(float), digits=1)])
    return rows


def action_level_section(out: Path, exp, markdown_table, draw=plots.draw) -> list[str]:
    """Future work 1's markdown lines; writes its two CSV tables and its figure (by `draw`, plots.draw's form)."""
    profiles, merges = profile_rows(exp), merge_rows(exp)
    for name, rows in (("action_profiles.csv", profiles), ("action_merges.csv", merges)):
        with open(out / name, "w", newline="") as f:
            csvcell.writer(f).writerows(rows)
    R = exp.picks.shape[1]
    labels = [f"{'+'.join(exp.merges[j])}: {key}" for j, key in exp.members]
    draw("grouped_bars_with_spread", labels, {s: exp.picks[k] for k, s in enumerate(exp.strategies)},
         [PERFECT_PICKS] * len(labels), out / "action_merges.png",
         f"merged policy played by each member, picks per round (epsilon 0; mean \u00b1 sd over {R} replicates)",
         "perfect play")
    change = exp.picks[-1] - exp.picks[0]  # (replicates, members)
    readers = [k for k in READING_PERSONAS if any(key == k for _, key in exp.members)]
    verdicts = []
    for k in readers + ["others"]:
        cols = [c for c, (_, key) in enumerate(exp.members) if (key == k if k != "others" else key not in readers)]
        d = change[:, cols].mean(axis=1)
        verdicts.append(f"{k}: {d.mean():+.2f} \u00b1 {d.std():.2f}")
    a3 = {k: exp.profiles[k].algorithm3 for k in exp.persona}
    al = {k: exp.profiles[k].info for k in exp.persona}
    dropped = [f"{k} ({_pct(a3[k].speech)}/{_pct(a3[k].head)} -> {_pct(al[k].speech)}/{_pct(al[k].head)})"
               for k in exp.persona if (a3[k].speech, a3[k].head) != (al[k].speech, al[k].head)]
    differ = int((exp.replicate_info[..., :2] != exp.replicate_info[..., 2:]).any(-1).sum())
    return [
        ACTION_LEVEL_HEADING, "",
        "The thesis's algorithm 3 compares a user's policies suggestion by suggestion (5.2.1), so two composite "
        "actions that mean the same to the user count as speech and head incompatibilities, and algorithm 4 "
        "merges policies part by part (5.2.2), so a pair a user understands only as one whole can be split; "
        "chapter 8 proposes extraction \"at action level\" (7.4: users gave suggestions meanings \"in "
        "combination with other suggestions\"). Three personas with the same features (focus 6, memory 3, "
        "hearing 6, sight 6; core/data/reading_personas.json, not in the study above): **plain** reads as the "
        "thesis's user; **duo** understands the words only while the head moves with them and a head turn only "
        "with words (\"together\"); **compass** reads a spoken direction with a perpendicular head turn as the "
        "diagonal between them (\"Maybe up\" + turn left = up-left, \"compound\"). Their partners are the "
        "study's tatiana, deaf and blind, each trained 10 games (the same games as above).", "",
        "Definitions (core/actionlevel.py): V(s, a) is the mean Q-value of whole action a over the user's "
        "policies that tried it; the user recognises a when V > 0 and rejects it when V < -0.5; a *whole* is "
        "a recognised action whose hearing part alone and visual part alone are both rejected. A state "
        "algorithm 3 counts is a *synonym* state (not counted at action level) when every policy's action there "
        "is recognised and the actions that are not wholes agree part by part: an impaired channel (blind's "
        "head) stays counted. Merging, *wholes kept*: algorithm 4 with the action-level information, then in "
        "each state its action is replaced by the action the most members recognise, when that is more "
        "members than recognise algorithm 4's (ties: the larger sum of V).", "",
        "Profiles over each persona's 10 policies, and over 5 replicates of 2 policies (as in the human study, "
        "7.2); shares of the 23 spatial states:", "",
        markdown_table(profiles), "",
        "Over 10 policies, action level lowers the counts of " + (", ".join(dropped) if dropped else "no persona")
        + f"; with 2 policies a user, disagreements are rarer and the two extractions differ in {differ} of "
        f"{exp.replicate_info.shape[0] * exp.replicate_info.shape[1]} replicate profiles.", "",
        f"Merges: in each of {R} replicates every member is represented by one of its two policies (the same "
        "one for every strategy) and each merged policy plays the same 4 evaluation games x 50 rounds of each "
        "member, epsilon 0. Picks per round, lower is better:", "",
        markdown_table(merges), "",
        "Change in picks per round of the merged policies, wholes kept minus algorithm 3 + 4, mean \u00b1 sd "
        "over the replicates (negative = fewer picks, better), by who played them: " + "; ".join(verdicts) +
        f". The action-level information alone changed "
        f"{counted(int(exp.info_changed.sum()), 'state')} of the {counted(exp.info_changed.size, 'merged policy', 'merged policies')} (it changes a merge only where it changes a member's error "
        "shares, and with 2 policies a user it seldom does); the change comes from keeping wholes.", "",
        "![action-level merges](action_merges.png)", "",
    ]

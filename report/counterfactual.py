"""What a counterfactual replay writes: the fitted user, the comparison table, the per-seed data, a figure.

Rule: one folder per run, filled in a temporary folder and renamed when
complete (pairplay.outputs.output_folder: an existing non-empty folder only
with force). Files: `<recording>.usermodel.json` (schemas/usermodel.py),
`counterfactual.csv` (arm, seed, round, picks: every simulated round),
`counterfactual.md` (the fitted user with its 95% sets, the comparison table
and the assumptions; a fit of a damaged or cut recording's intact parts says so
in its header, as the user model's `partial` does: reader.EventLog.note) and `counterfactual.png` (picks per round by round, and
the share of turns whose second pick matched, per arm: HITS). Arms are summarised
over seeds: mean, sample sd, 95% t-interval of the mean, clipped to the values
the measure can take: a share's to 0..100% (near 100% the t-interval of a mean
of shares passed it, `91.9% [83.7%, 100.2%]`, a share no seed can reach), picks
per round's at 18 below, in the table and the figure's band (`final 27.33 ±
3.77 [-6.55, 61.22]` of 2 seeds: no round takes fewer than 18 picks, a perfect
one; report/sweep.py clips its picks measures the same, `measure_bounds`); the
clip moves no bound a mean can take, so the interval still holds the true mean
as often. A paired difference has no such bound and is not clipped. Each arm beside the
recorded learner replayed on the same seeds ("same"), as a paired difference
per seed; "differs" when that difference's 95% interval leaves out 0.
Written with force over an earlier run, the earlier run's files of these names
that this one does not write are removed (COUNTERFACTUAL_OUTPUTS: the table and
figure of a run that now fits the user alone, another recording's user model),
only those its manifest (COUNTERFACTUAL_MANIFEST) says a run wrote: a user's
`alice.usermodel.json` there stays.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from pairplay import csvcell
from pairplay.core.geometry import PERFECT_PICKS, PICKS_UNIT
from pairplay.outputs import manifest_name, output_folder
from pairplay.schemas.usermodel import UserModelFile, write_user_model

from .study import markdown_table, text_table
from .sweep import PICKS, t975
from pairplay.numbers import counted

ARM_TEXT = {
    "same": "the recorded learner, replayed (checks the fit)",
    "q": "Q-learning from scratch, the recorded schedule",
    "final": "the recorded learner's final policy, fixed",
    "oracle": "the oracle's policy for the fitted user",
    "alone": "no suggestion (the user alone)",
}


class Summary(NamedTuple):
    mean: float
    sd: float
    low: float
    high: float


def summarise(values: np.ndarray, within: tuple[float, float] | None = None) -> Summary:
    """Mean, sample sd and 95% t-interval of the mean of per-seed values, clipped to `within` if given
    (SHARE for shares: module rule)."""
    v = np.asarray(values, dtype=float)
    n = v.size
    mean = float(v.mean())
    sd = float(v.std(ddof=1)) if n > 1 else 0.0
    half = t975(n) * sd / math.sqrt(n) if n > 1 else 0.0
    low, high = mean - half, mean + half
    if within is not None:
        low, high = max(low, within[0]), min(high, within[1])
    return Summary(mean, sd, low, high)


SHARE = (0.0, 1.0)  # the bounds of a share (HITS)


# the hits column: in every arm but "alone" each turn has a suggestion, so it is the share of suggestions
# followed by a match; "alone" suggests nothing, so there it is the user's own share, the baseline (before,
# the column said "suggestions followed by a match" for "alone" too: a new user's trial)
HITS = "turns whose second pick matched (alone: unaided)"


class Recorded(NamedTuple):
    picks: list[int]  # per complete round
    hits: float  # share of the turns with a suggestion whose second pick matched
    suggestions: int


def comparison_rows(recorded: Recorded, runs: dict, texts: dict[str, str]) -> list[list[str]]:
    """The comparison table: header first; picks are means over each seed's rounds."""
    rows = [["arm", "what", f"{PICKS_UNIT}: mean \u00b1 sd [95% CI]", HITS,
             "minus recorded", "minus 'same' (paired) [95% CI]", "differs from 'same'"]]
    rec_mean = float(np.mean(recorded.picks)) if recorded.picks else float("nan")
    rows.append(["recorded", "what happened", f"{rec_mean:.2f} ({counted(len(recorded.picks), 'round')})",
                 f"{recorded.hits:.1%} of {recorded.suggestions}", "", "", ""])
    base = runs["same"].picks.mean(axis=1) if "same" in runs else None
    for name, r in runs.items():
        per_seed = r.picks.mean(axis=1)
        s, h = summarise(per_seed, PICKS), summarise(r.hits, SHARE)
        paired, differs = "", ""
        if base is not None and name != "same":
            d = summarise(per_seed - base)
            paired = f"{d.mean:+.2f} [{d.low:+.2f}, {d.high:+.2f}]"
            differs = "yes" if d.low > 0 or d.high < 0 else "no"
        rows.append([name, texts.get(name, name), f"{s.mean:.2f} \u00b1 {s.sd:.2f} [{s.low:.2f}, {s.high:.2f}]",
                     f"{h.mean:.1%} [{h.low:.1%}, {h.high:.1%}]", f"{s.mean - rec_mean:+.2f}", paired, differs])
    return rows


def model_rows(model: UserModelFile) -> list[list[str]]:
    rows = [["feature", "estimate", "what it means", "95% set (profile likelihood)", "identified"]]
    for name in ("focus", "hearing", "sight", "memory"):
        f = getattr(model, name)
        rows.append([name, str(f.level), f.means, ", ".join(map(str, f.set95)), "yes" if f.identified else "no"])
    for name, r in (("p (consider)", model.p_consider), ("q (hear)", model.q_hear)):
        rows.append([name, f"{r.estimate:.2f}", "on a 0.01 grid, the rest at the estimate",
                     f"{r.low95:.2f} .. {r.high95:.2f}", ""])
    rows.append(["lapse", f"{model.lapse:g}", "share of picks off the model (fit only)", "", ""])
    return rows


def caveats(model: UserModelFile) -> list[str]:
    """What the reader must know before trusting the fitted user (empty when nothing)."""
    out = []
    vague = [n for n in ("focus", "hearing", "sight", "memory") if not getattr(model, n).identified]
    if vague:
        out.append(f"the session cannot tell the levels of {', '.join(vague)} apart (every level is in the 95% set): "
                   "the fitted user takes the lowest level of the highest likelihood there")
    if model.lapse >= 0.3:
        out.append(f"lapse {model.lapse:g}: the fit explains the picks as {model.lapse:.0%} uniform picks; the "
                   "participant is far from the simulated user, and the arms replay a persona that mostly failed to fit")
    return out


def picks_band(picks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per round (columns of seeds x rounds): the mean over seeds and its 95% t-interval, clipped at 18 (PICKS:
    module rule)."""
    mean = picks.mean(axis=0)
    n = picks.shape[0]
    half = t975(n) * picks.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.zeros_like(mean)
    return mean, np.clip(mean - half, *PICKS), np.clip(mean + half, *PICKS)


def counterfactual_figure(recorded: Recorded, runs: dict, path: Path, title: str) -> None:
    from .plots import pyplot, save_figure

    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (name, r) in enumerate(runs.items()):
        x = np.arange(1, r.picks.shape[1] + 1)
        mean, low, high = picks_band(r.picks)
        n = r.picks.shape[0]
        c = colours[k % len(colours)]
        ax.plot(x, mean, color=c, lw=1.5, label=f"{name} (mean of {counted(n, 'seed')})")
        ax.fill_between(x, low, high, color=c, alpha=0.18, lw=0)
    if recorded.picks:
        ax.plot(np.arange(1, len(recorded.picks) + 1), recorded.picks, color="black", lw=2, marker="o", ms=3,
                label="recorded")
    ax.axhline(PERFECT_PICKS, color="grey", ls=":", lw=1)
    ax.set_xlabel("round")
    ax.set_ylabel(PICKS_UNIT)
    ax.set_title("picks per round (band: 95% CI over seeds)", fontsize=9)
    ax.legend(fontsize=7)
    names = list(runs)
    stats = [summarise(runs[n].hits, SHARE) for n in names]
    bx.bar(names, [s.mean for s in stats], yerr=[[s.mean - s.low for s in stats], [s.high - s.mean for s in stats]],
           color=[colours[k % len(colours)] for k in range(len(names))], capsize=4)
    bx.axhline(recorded.hits, color="black", lw=2, label=f"recorded ({recorded.hits:.0%})")
    bx.set_ylim(0, 1)
    bx.set_ylabel(HITS)
    bx.set_title("suggestion success (bars: 95% CI over seeds)", fontsize=9)
    bx.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, 110)


COUNTERFACTUAL_OUTPUTS = ("*.usermodel.json", "counterfactual.csv", "counterfactual.md", "counterfactual.png")
COUNTERFACTUAL_MANIFEST = manifest_name("counterfactual")  # the files it wrote there: --force removes only those


def write_counterfactual(out: str | Path, stem: str, model: UserModelFile, recorded: Recorded | None,
                         runs: dict | None, texts: dict[str, str], force: bool = False, read_whole: str = "") -> list[Path]:
    """Fill the folder `out` (see the module rule); `runs` None writes the fitted user alone. `read_whole`: a
    damage of the recording that lost no event (reader.EventLog.loss_free), said in the header too."""
    written = []
    with output_folder(out, force, owned=COUNTERFACTUAL_OUTPUTS, manifest=COUNTERFACTUAL_MANIFEST) as tmp:
        write_user_model(tmp / f"{stem}.usermodel.json", model)
        written.append(f"{stem}.usermodel.json")
        lines = [f"# Counterfactual replay of {model.recording}", ""]
        if model.partial:  # a fit of intact parts only: said where the results are read
            lines += [f"**Partial recording:** fitted on the intact parts only ({model.partial}).", ""]
        elif read_whole:  # fitted on every event, the damage said where the results are read
            lines += [f"**Damaged recording, no event lost:** fitted on every event ({read_whole}).", ""]
        lines += [f"Session {model.session}, participant {model.participant}, observed card: "
                  f"{model.observed_source}. The simulated user fitted to the recorded picks"
                  f"{' of ' + ', '.join(model.fitted_on) if len(model.fitted_on) > 1 else ''} "
                  f"(maximum likelihood over {counted(model.picks, 'pick')}, log L = {model.loglik:.1f}; "
                  f"evidence: {', '.join(f'{k} {v}' for k, v in model.evidence.items())}):", "",
                  markdown_table(model_rows(model)), ""]
        lines += [f"**Caveat:** {c}." for c in caveats(model)] + ([""] if caveats(model) else [])
        if model.considered_counted is not None:
            c = model.considered_counted
            lines += [f"Check: the simulated participant reported considering {c.count} of {counted(c.of, 'suggestion')} "
                      f"whose match it did not remember ({c.rate:.2f}, 95% {c.low95:.2f} .. {c.high95:.2f}); the "
                      f"fit's p is {model.p_consider.estimate:.2f}.", ""]
        if runs:
            rows = comparison_rows(recorded, runs, texts)
            n = next(iter(runs.values())).picks.shape
            lines += ["## Recorded vs counterfactual", "",
                      f"Each arm plays the fitted user for {counted(n[1], 'round')} on {counted(n[0], 'seed')} (the same deals in every "
                      "arm); picks per round are each seed's mean over its rounds, lower is better "
                      f"({PERFECT_PICKS} = perfect).", "", markdown_table(rows), "",
                      "![counterfactual](counterfactual.png)", ""]
            with open(tmp / "counterfactual.csv", "w", newline="") as f:
                w = csvcell.writer(f)
                w.writerow(["arm", "seed", "round", "picks"])
                for name, r in runs.items():
                    for s in range(r.picks.shape[0]):
                        w.writerows([name, s, k + 1, int(v)] for k, v in enumerate(r.picks[s]))
            counterfactual_figure(recorded, runs, tmp / "counterfactual.png",
                                  f"{model.recording}: recorded vs counterfactual, fitted user "
                                  f"F{model.focus.level} H{model.hearing.level} S{model.sight.level} "
                                  f"M{model.memory.level}")
            written += ["counterfactual.csv", "counterfactual.png"]
        lines += ["## Assumptions of the fit", ""] + [f"- {a}" for a in model.assumptions] + [""]
        (tmp / "counterfactual.md").write_text("\n".join(lines), encoding="utf-8")
        written.append("counterfactual.md")
    return [Path(out) / w for w in written]


def console_text(model: UserModelFile, recorded: Recorded | None, runs: dict | None, texts: dict[str, str]) -> str:
    parts = [text_table(model_rows(model))] + [f"caveat: {c}" for c in caveats(model)]
    if runs:
        parts.append(text_table(comparison_rows(recorded, runs, texts)))
    return "\n\n".join(parts)

"""Figures of the study report (matplotlib, headless Agg backend).

Rule: one function per figure, each takes plain arrays and a path and writes a
PNG; nothing here computes results. Every figure explains itself: each axis
says its quantity and unit (performance is always picks per round, 18 =
perfect), each shaded band and reference line is in a legend, and panels that
are compared share their y-range. A figure is written through a temporary file
(pairplay.outputs), so a reader never sees half a PNG.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def pyplot():
    """matplotlib's pyplot on the headless Agg backend, imported on first use (the study draws in a child)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt

from pairplay.core.geometry import PERFECT_PICKS, PICKS_UNIT  # noqa: E402
from pairplay.numbers import counted


def _fit(fig, left: float, bottom: float, top: float, right: float = 0.15, wspace: float | None = None,
         hspace: float | None = None) -> None:
    """Place the axes with fixed margins in inches (text sizes are in points, so margins in inches
    fit any figure width), instead of `tight_layout`.

    Why: tight_layout measures every tick label, title and legend by laying the figure out
    once more before it is drawn; that was 40% of the study's figure CPU (issue 16: the figure
    process is the study's last to finish). The margins are tight_layout's own on the study's
    figures (measured), with tick labels that vary (persona names, rotated) measured by
    `_label_depth`. `wspace`/`hspace` are fractions of the mean axes width/height (matplotlib's)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=wspace, hspace=hspace)


TICK_ROOM = 0.29  # inches under rotated tick labels: the tick, its pad and the figure's edge (tight_layout's)


def _under_labels(labels, rotation: float, fontsize: float = 10.0) -> float:
    """The bottom margin (inches) under rotated tick labels: at least 0.6 (a centred y label as
    long as the axes is high needs it), else the labels' depth and `TICK_ROOM`."""
    return max(0.6, TICK_ROOM + _label_depth(labels, rotation, fontsize))


def _left_of_labels(labels, rotation: float, base: float, fontsize: float = 10.0, share: float = 1.0) -> float:
    """The left margin (inches): `base`, or more when the first tick label, rotated and anchored
    at its tick by its right end (`share` 1) or its centre (0.5), reaches further left."""
    if not labels:
        return base
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    width, _, _ = TextToPath().get_text_width_height_descent(str(labels[0]), FontProperties(size=fontsize),
                                                             ismath=False)
    return max(base, share * width * np.cos(np.deg2rad(rotation)) / 72.0 + 0.1)


def _label_depth(labels, rotation: float, fontsize: float = 10.0) -> float:
    """Inches the longest of `labels`, rotated by `rotation` degrees, reaches below its axis
    (font metrics only: nothing is laid out)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    measure, prop = TextToPath(), FontProperties(size=fontsize)
    a = np.deg2rad(rotation)
    depth = 0.0
    for label in labels:
        width, height, _ = measure.get_text_width_height_descent(str(label), prop, ismath=False)
        depth = max(depth, width * np.sin(a) + height * np.cos(a))
    return depth / 72.0

# Figure 6.4: which feature each panel isolates, and the two personas compared.
FIGURE_6_4 = (
    ("memory", "vincent", "frances"),
    ("focus", "helmut", "wasim"),
    ("impairment", "deaf", "blind"),
)


def _smooth(x: np.ndarray, window: int) -> np.ndarray:
    if window <= 1 or x.size < window:
        return x
    kernel = np.ones(window) / window
    pad = np.concatenate([np.full(window // 2, x[0]), x, np.full(window - 1 - window // 2, x[-1])])
    return np.convolve(pad, kernel, mode="valid")


def learning_curves(curves: dict[str, np.ndarray], names: dict[str, str], path: Path,
                    smooth: int = 10) -> list[str]:
    """Figure 6.4: picks per round, mean over games with a +-1 std band, one panel per feature.

    `curves[persona]` is (games, rounds). Panels whose personas are missing are
    left out; returns the panel titles drawn.
    """
    plt = pyplot()
    panels = [(f, a, b) for f, a, b in FIGURE_6_4 if a in curves and b in curves]
    if not panels:
        panels = [("all", *list(curves)[:2])] if len(curves) >= 2 else [("all", next(iter(curves)), None)]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 3.8), squeeze=False, sharey=True)
    for ax, (feature, *keys) in zip(axes[0], panels):
        for key in (k for k in keys if k):
            picks = curves[key]
            mean, std = picks.mean(0), picks.std(0)
            rounds = np.arange(1, picks.shape[1] + 1)
            line, = ax.plot(rounds, _smooth(mean, smooth), label=names.get(key, key), lw=1.4)
            ax.fill_between(rounds, _smooth(mean - std, smooth), _smooth(mean + std, smooth),
                            color=line.get_color(), alpha=0.18, lw=0)
        ax.set_title(f"{feature}")
        ax.set_xlabel("round")
        ax.grid(alpha=0.3)
        ax.legend(frameon=False)
    axes[0][0].set_ylabel(PICKS_UNIT)
    fig.suptitle(f"mean over games, {smooth}-round moving window; shaded band: \u00b11 sd over games", fontsize=9)
    _fit(fig, left=0.7, bottom=0.6, top=0.7, wspace=0.06)
    save_figure(fig, path, dpi=110)
    return [p[0] for p in panels]


def comparison_bars(labels: list[str], series: dict[str, np.ndarray], path: Path, ylabel: str,
                    title: str = "") -> None:
    """Grouped bars: one group per label, one bar per series (e.g. alone/learned/oracle)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(labels) + 2), 3.8))
    width = 0.8 / len(series)
    x = np.arange(len(labels))
    for i, (name, values) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * width, values, width, label=name)
    ax.set_xticks(x, labels, rotation=20)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(frameon=False, ncol=len(series))
    _fit(fig, left=_left_of_labels(labels, 20, 0.7, share=0.5), bottom=_under_labels(labels, 20),
         top=0.4 if title else 0.2)
    save_figure(fig, path, dpi=110)


def profiles(keys: list[str], names: dict[str, str], infos: list, features: list[tuple[int, int, int, int]],
             path: Path, trained: list | None = None, min_updates: int = 0) -> None:
    """Figure 6.5: extracted user information beside the persona's features.

    `trained` (optional, one UserInfo or None per persona): the same shares over
    the well-trained states only, drawn as black ticks on the bars.
    """
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.2))
    x = np.arange(len(keys))
    left.bar(x - 0.2, [100 * i.speech for i in infos], 0.4, label="speech incompatibility %")
    left.bar(x + 0.2, [100 * i.head for i in infos], 0.4, label="head incompatibility %")
    if trained is not None:
        for offset, field in ((-0.2, "speech"), (0.2, "head")):
            shown = [(xi + offset, 100 * getattr(t, field)) for xi, t in zip(x, trained) if t is not None]
            if shown:
                left.scatter(*zip(*shown), marker="_", s=300, color="black", lw=2, zorder=3,
                             label=f"over states updated >= {min_updates}x" if field == "speech" else None)
    for xi, info in zip(x, infos):
        left.text(xi, 103, ("S" if info.facial else "-") + ("G" if info.gaze else "-"), ha="center", fontsize=9)
    left.set_ylim(0, 140)
    left.set_yticks(range(0, 101, 20))
    left.set_ylabel("incompatible states, % of the 23 spatial states")
    left.set_xticks(x, [names.get(k, k) for k in keys], rotation=25, ha="right")
    left.set_title("extracted user information (S: smile used, G: gaze used)")
    left.legend(frameon=False, fontsize=8, loc="upper left", ncol=2)
    feats = np.array(features)
    for j, label in enumerate(("focus", "memory", "hearing", "sight")):
        right.bar(x + (j - 1.5) * 0.2, feats[:, j], 0.2, label=label)
    right.set_xticks(x, [names.get(k, k) for k in keys], rotation=25, ha="right")
    right.set_ylim(0, 7.2)
    right.set_yticks(range(0, 7))
    right.set_ylabel("feature level (1 = weakest, 6 = best)")
    right.set_title("persona features (appendix A, 1..6)")
    right.legend(frameon=False, fontsize=8, ncol=4, loc="upper left")
    shown = [names.get(k, k) for k in keys]
    _fit(fig, left=_left_of_labels(shown, 25, 0.75), bottom=_under_labels(shown, 25), top=0.4,
         wspace=0.13)
    save_figure(fig, path, dpi=110)


def merged_policies(panels: list[tuple[str, dict[str, np.ndarray], np.ndarray]], state_count: int,
                    path: Path) -> None:
    """Figure 6.6: state code vs action code of the input policies and their merge (blue x)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.2), squeeze=False)
    markers = ["o", "s", "^", "v", "D", "P", "*", "h"]
    states = np.arange(state_count)
    for ax, (title, inputs, merged) in zip(axes[0], panels):
        for (name, policy), marker in zip(inputs.items(), markers):
            ax.scatter(states, policy[:state_count], marker=marker, facecolors="none",
                       edgecolors="0.45", s=28, label=name, lw=0.8)
        ax.scatter(states, merged[:state_count], marker="x", color="tab:blue", s=40, label="merged", lw=1.4)
        ax.axhspan(32.5, 43.5, color="tab:blue", alpha=0.07, lw=0,
                   label='codes 33-43: "exact position" speech')
        ax.set_xlabel(f"state code (0..{state_count - 1}, core/geometry.py)")
        ax.set_ylabel("action code (0..87, core/actions.py)")
        ax.set_ylim(-2, 90)
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(frameon=False, fontsize=8, loc="upper right")
    _fit(fig, left=0.7, bottom=0.6, top=0.4, wspace=0.14)
    save_figure(fig, path, dpi=110)


def reuse_curves(keys: list[str], names: dict[str, str], curves: np.ndarray, oracle: list[float],
                 path: Path, smooth: int = 10) -> None:
    """Online picks per round, Q-learning from scratch vs pi-reuse, one small panel per held-out persona."""
    plt = pyplot()
    cols = 4
    rows = (len(keys) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.6 * rows), squeeze=False, sharex=True, sharey=True)
    drawn = []
    for ax, key, c, o in zip(axes.flat, keys, curves, oracle):
        drawn += [_smooth(c[0], smooth), _smooth(c[1], smooth)]
        ax.plot(drawn[-2], label="from scratch", lw=1.1)
        ax.plot(drawn[-1], label="pi-reuse", lw=1.1)
        ax.axhline(o, color="0.3", lw=0.8, ls="--", label="oracle")
        ax.set_title(names.get(key, key), fontsize=9)
        ax.grid(alpha=0.3)
    # one y-range for every panel, holding every curve and every oracle line
    low = min([PERFECT_PICKS, *oracle, *(float(d.min()) for d in drawn)])
    high = max([*oracle, *(float(d.max()) for d in drawn)])
    axes.flat[0].set_ylim(low - 0.03 * (high - low) - 0.5, high + 0.03 * (high - low) + 0.5)
    for ax in axes.flat[len(keys):]:
        ax.axis("off")
    axes.flat[0].legend(frameon=False, fontsize=7)
    fig.supxlabel("round")
    fig.supylabel(f"{PICKS_UNIT}, {smooth}-round mean")
    _fit(fig, left=0.8, bottom=0.75, top=0.35, wspace=0.07, hspace=0.22)
    save_figure(fig, path, dpi=100)


def save_figure(fig, path: Path, dpi: int, force: bool = False) -> None:
    """Write the figure whole or not at all (a temporary file renamed; pairplay.outputs); `force`
    replaces an existing one. A refusal by the system is an OSError naming `path`."""
    from pairplay.outputs import output_path

    with output_path(path, force) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    pyplot().close(fig)


FIGURES = ("learning_curves", "comparison_bars", "profiles", "merged_policies", "reuse_curves", "algorithm_curves",
           "grouped_bars_with_spread", "frame_calibration")


def draw(name: str | None, *args) -> None:
    """Draw figure `name` (one of FIGURES) with `args`; None imports matplotlib only (a child process warming up).

    The study calls this in a child process: arguments are plain data, so the
    child imports matplotlib and numpy only.
    """
    if name is None:  # the study's figure process starts with this: matplotlib loads while the study computes
        pyplot()
        return
    if name not in FIGURES:
        raise ValueError(f"unknown figure {name!r}")
    globals()[name](*args)


def grouped_bars_with_spread(labels: list[str], series: dict[str, np.ndarray], reference: list[float],
                             path: Path, title: str, reference_label: str = "oracle") -> None:
    """Bars per label and series: the mean over replicates with a 1-sd error bar; a tick marks the reference.

    `series[name]` is (replicates, labels) in picks per round."""
    plt = pyplot()
    n = len(series)
    width = 0.8 / n
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(labels) + 2), 4.2))
    for i, (name, values) in enumerate(series.items()):
        values = np.asarray(values)
        ax.bar(x + (i - (n - 1) / 2) * width, values.mean(axis=0), width, yerr=values.std(axis=0),
               capsize=2, label=name)
    ax.scatter(x, reference, marker="_", s=400, color="black", zorder=3, label=reference_label)
    ax.set_xticks(x, labels, rotation=20, ha="right", rotation_mode="anchor")  # each label ends at its bars
    ax.set_ylabel("picks per round (18 = perfect; lower is better)")
    ax.set_ylim(16, max(float(np.max([np.asarray(v).max() for v in series.values()])), max(reference)) + 2)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, ncol=2)
    _fit(fig, left=_left_of_labels(labels, 20, 0.7), bottom=_under_labels(labels, 20), top=0.4)
    save_figure(fig, path, dpi=110)


def sweep_measure(labels: list[str], mean: list[float], low: list[float], high: list[float], path: Path,
                  measure: str, seeds: int) -> None:
    """One sweep measure across the grid: the mean over seeds with its 95% confidence interval."""
    plt = pyplot()
    mean, low, high = map(np.asarray, (mean, low, high))
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(max(6.0, 0.28 * len(labels) + 3), 4.2))
    ax.errorbar(x, mean, yerr=[mean - low, high - mean], fmt="o", capsize=3, markersize=4)
    ax.set_xticks(x, labels, rotation=60, ha="right", fontsize=7)
    unit = {"ratio": "learned / oracle (1 = the oracle)", "reuse_gain": "picks per round saved by pi-reuse"}
    ax.set_ylabel(unit.get(measure.split("/")[-1], "picks per round (18 = perfect)"))
    ax.set_title(f"{measure}: mean over {counted(seeds, 'seed')}, 95% confidence interval", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=100, force=True)  # a resumed sweep draws its figures again


def human_curves(curves: dict[str, np.ndarray], path: Path, title: str, dashed: tuple[str, ...] = ()) -> None:
    """Figures 7.3 and 7.6: mean picks per round, one line per game, phase or group.

    As in the thesis, Q-learning curves are drawn with circles and pi-reuse ones
    with diamonds: a label naming a reuse phase or a phase-2 group gets diamonds
    when it is in `dashed` or contains "phase2"; 18 (perfect play) is marked."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.6, 3.8))
    for label, c in curves.items():
        rounds = np.arange(1, len(c) + 1)
        marker = "D" if (label in dashed or "phase2" in label or "users" in label) else "o"
        ax.plot(rounds, c, marker=marker, ls="--" if label in dashed else "-", label=label, lw=1.4, ms=5)
    ax.axhline(18, color="0.5", lw=0.8, ls=":", label="perfect play (18)")
    ax.set_xlabel("round")
    ax.set_ylabel("picks per round (mean)")
    if curves:
        ax.set_xticks(np.arange(1, max(len(c) for c in curves.values()) + 1))
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def human_merged(panels: list[tuple[str, np.ndarray]], reference: tuple[str, np.ndarray] | None,
                 state_count: int, path: Path) -> None:
    """Figure 7.5: state code vs action code of each merged policy (blue x), a reference (green +)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(5.6 * len(panels), 4.2), squeeze=False)
    states = np.arange(state_count)
    for ax, (title, merged) in zip(axes[0], panels):
        if reference is not None:
            ax.scatter(states, reference[1][:state_count], marker="+", color="tab:green", s=70, lw=1.4,
                       label=reference[0])
        ax.scatter(states, merged[:state_count], marker="x", color="tab:blue", s=40, lw=1.4, label=title)
        ax.axhspan(32.5, 44.5, color="tab:blue", alpha=0.07, lw=0)  # "exact position" speech, codes 33-44
        ax.set_xlabel("state code")
        ax.set_ylabel("action code")
        ax.set_ylim(-2, 90)
        ax.grid(alpha=0.3)
        ax.legend(frameon=False, fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def algorithm_curves(curves: np.ndarray, algorithms: list[str], personas: list[str], names: dict[str, str],
                     oracle: list[float], path: Path, smooth: int = 10) -> None:
    """Learners side by side: one panel per persona, picks per round (mean over games, +-1 sd band).

    `curves` is (n_alg, P, games, rounds); the oracle's picks per round are a dashed line.
    """
    plt = pyplot()
    n = len(personas)
    cols = min(4, n)
    rows_ = -(-n // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(4.2 * cols, 3.2 * rows_), squeeze=False, sharey=True)
    for i, key in enumerate(personas):
        ax = axes[i // cols][i % cols]
        for a, alg in enumerate(algorithms):
            picks = curves[a, i]
            mean, std = picks.mean(0), picks.std(0)
            rounds = np.arange(1, picks.shape[1] + 1)
            line, = ax.plot(rounds, _smooth(mean, smooth), label=alg, lw=1.3)
            ax.fill_between(rounds, _smooth(mean - std, smooth), _smooth(mean + std, smooth),
                            color=line.get_color(), alpha=0.18, lw=0)
        ax.axhline(oracle[i], color="k", ls="--", lw=0.8, label="oracle")
        ax.set_title(names.get(key, key), fontsize=10)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(frameon=False, fontsize=8)
    for j in range(n, rows_ * cols):
        axes[j // cols][j % cols].axis("off")
    for r in range(rows_):
        axes[r][0].set_ylabel("picks per round")
    fig.suptitle(f"online picks per round, mean over games ({smooth}-round window); band: \u00b11 sd over games",
                 fontsize=9)
    _fit(fig, left=0.8, bottom=0.6, top=0.65, wspace=0.07, hspace=0.3)
    save_figure(fig, path, dpi=100)


def frame_calibration(labels: list[str], series: dict[str, np.ndarray], lengths: list[int], accuracy: np.ndarray,
                      path: Path, replicates: int, sessions: int) -> None:
    """Future work 2: merged policies across mirrored users (left) and the calibration round's accuracy (right).

    `series[arm]` is (replicates, personas) picks per round; `accuracy` is (personas, lengths), shares 0..1."""
    plt = pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12.5, 4.4), gridspec_kw={"width_ratios": [2.2, 1]})
    width = 0.8 / len(series)
    x = np.arange(len(labels))
    for i, (name, values) in enumerate(series.items()):
        values = np.asarray(values)
        ax.bar(x + (i - (len(series) - 1) / 2) * width, values.mean(axis=0), width, yerr=values.std(axis=0),
               capsize=2, label=name)
    ax.axhline(PERFECT_PICKS, color="0.3", lw=0.8, ls="--", label=f"perfect play ({PERFECT_PICKS})")
    ax.set_xticks(x, labels, rotation=12, fontsize=8)
    ax.set_ylabel("picks per round (18 = perfect; lower is better)")
    ax.set_ylim(PERFECT_PICKS - 1, max(float(np.asarray(v).max()) for v in series.values()) + 3)
    ax.set_title(f"one merged policy for all the users, played to each (mean \u00b1 sd over {counted(replicates, 'replicate')})",
                 fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, ncol=3, frameon=False, loc="upper left")
    markers = "osD^v<>"
    for i, (label, acc) in enumerate(zip(labels, accuracy)):  # markers and dashes: lines at 100% overlap
        ax2.plot(lengths, 100 * np.asarray(acc), marker=markers[i % len(markers)], ls=("-", "--", ":")[i % 3],
                 lw=1.2, ms=7 - i, label=label)
    ax2.set_xlabel("suggestions in the calibration round")
    ax2.set_ylabel("frame inferred right (% of rounds)")
    ax2.set_xticks(lengths)
    ax2.set_ylim(min(50.0, 100 * float(np.min(accuracy)) - 5), 101)
    ax2.set_title(f"calibration round, {counted(sessions, 'round')} per user and length", fontsize=9)
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7, frameon=False, loc="lower right")
    _fit(fig, left=_left_of_labels(labels, 12, 0.8, 8, share=0.5), bottom=max(0.75, _under_labels(labels, 12, 8)),
         top=0.4, wspace=0.13)
    save_figure(fig, path, dpi=100)

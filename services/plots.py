"""Figures of the study report (matplotlib, headless Agg backend).

Rule: one function per figure, each takes plain arrays and a path and writes a
PNG; nothing here computes results.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

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
    axes[0][0].set_ylabel("picks per round")
    fig.suptitle(f"mean over games, {smooth}-round moving window; band: \u00b11 sd over games", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [p[0] for p in panels]


def comparison_bars(labels: list[str], series: dict[str, np.ndarray], path: Path, ylabel: str,
                    title: str = "") -> None:
    """Grouped bars: one group per label, one bar per series (e.g. alone/learned/oracle)."""
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

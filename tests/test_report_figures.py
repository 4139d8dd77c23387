"""Output that cannot mislead: one unit (picks per round, 18 = perfect) and self-explaining figures.

The figures are drawn by the report's own functions with a capture in place of
the PNG writer, and their axes, bands and legends read back from matplotlib.
"""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from pairplay.core.geometry import PICKS_UNIT
from pairplay.report import plots
from pairplay.report.study import StudySettings, run_study

SMALL = StudySettings(personas="blind,deaf,tatiana", games=2, rounds=30, eval_rounds=3, reuse_seeds=2,
                      reuse_last=10)


@pytest.fixture
def figures(monkeypatch):
    drawn = {}

    def capture(fig, path, dpi):
        drawn[path.name] = fig
    monkeypatch.setattr(plots, "save_figure", capture)
    return drawn


def _legend_texts(ax) -> list[str]:
    legend = ax.get_legend()
    return [t.get_text() for t in legend.get_texts()] if legend else []


def test_reuse_panels_share_one_y_range_holding_every_oracle_line(figures):
    curves = np.stack([np.stack([np.full(100, 40.0 - i), np.full(100, 30.0)]) for i in range(3)])
    oracle = [18.0, 19.0, 27.5]  # one far from the others: it must still be on its axis
    plots.reuse_curves(["a", "b", "c"], {}, curves, oracle, plots.Path("reuse.png"))
    axes = [ax for ax in figures["reuse.png"].axes if ax.get_visible() and ax.axison]
    ranges = {ax.get_ylim() for ax in axes}
    assert len(ranges) == 1, ranges
    low, high = ranges.pop()
    assert all(low < o < high for o in oracle) and low < 18 and high > 40
    assert PICKS_UNIT in figures["reuse.png"]._supylabel.get_text()


def test_merged_profiles_and_learning_curves_say_what_their_axes_and_bands_are(figures):
    policy = np.arange(24) % 88
    plots.merged_policies([("a+b", {"a": policy, "b": policy}, policy), ("all", {}, policy)], 23,
                          plots.Path("merged.png"))
    for ax in figures["merged.png"].axes:
        assert ax.get_xlabel() and ax.get_ylabel()
        assert any('"exact position" speech' in t for t in _legend_texts(ax))  # the shaded band, named
    from pairplay.schemas.policy import UserInfo
    info = UserInfo(speech=0.1, head=0.2, facial=False, gaze=True, compared_states=23)
    plots.profiles(["a"], {}, [info], [(1, 2, 3, 4)], plots.Path("profiles.png"))
    left, right = figures["profiles.png"].axes
    assert "% of the 23 spatial states" in left.get_ylabel() and "feature level" in right.get_ylabel()
    plots.learning_curves({"vincent": np.full((2, 30), 20.0), "frances": np.full((2, 30), 22.0)}, {},
                          plots.Path("curves.png"))
    assert figures["curves.png"].axes[0].get_ylabel() == PICKS_UNIT


class _Recorder:
    def __init__(self, log, desc):
        self.log, self.desc = log, desc

    def update(self, n):
        self.log.append((self.desc, n))


def test_every_progress_bar_only_moves_forward_and_ends_full(tmp_path):
    log: list[tuple[str, int]] = []
    totals: dict[str, int] = {}

    def bar(total, desc):
        totals[desc] = total
        return contextlib.nullcontext(_Recorder(log, desc))
    report = run_study(SMALL, tmp_path / "study", bar)
    for desc, total in totals.items():
        steps = [n for d, n in log if d == desc]
        assert all(n >= 0 for n in steps), (desc, [n for n in steps if n < 0])  # never back to 0 halfway
        assert sum(steps) == total, (desc, sum(steps), total)
    assert "speed-up" in totals
    md = (report.out / "report.md").read_text()
    if "Where learned policies stay above the oracle" in md:  # the plurality says how many policies chose it
        assert "the plurality action (k of n policies)" in md and " of 2)" in md


def test_a_ctrl_c_while_the_figure_process_starts_leaves_no_process(monkeypatch):
    """The study's figure process is started before the study's try block: an interruption in
    that window used to leave the child running (and a leaked semaphore reported at exit).
    Only the children this pool started are counted: another test's child (a Dask nanny's
    worker, a pool still shutting down) may come and go meanwhile in the same process."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from pairplay.report import study as report_study

    real = ProcessPoolExecutor.submit
    started = []

    def submit(self, *args, **kwargs):
        real(self, *args, **kwargs)  # the child has been started
        started.extend(self._processes.values())
        raise KeyboardInterrupt

    monkeypatch.setattr(ProcessPoolExecutor, "submit", submit)
    with pytest.raises(KeyboardInterrupt):
        report_study._Figures(True)
    assert started and not [p for p in started if p.is_alive()]
    assert not set(started) & set(multiprocessing.active_children())


def _drawn_tick_labels(ax) -> list:
    """The tick labels matplotlib draws: those of ticks inside the view limits."""
    out = []
    for axis in (ax.xaxis, ax.yaxis):
        low, high = sorted(axis.get_view_interval())
        out += [t.label1 for t in axis.get_major_ticks() if low - 1e-9 <= t.get_loc() <= high + 1e-9]
    return out


@pytest.mark.parametrize("labels", [["Deaf", "Blind"], ["Vincent Cornaros", "Frances Miller", "Tatiana Modric"],
                                    ["duo+compass+deaf+blind: compass", "Carla (columns from the right)"]])
def test_fixed_margins_keep_every_label_and_title_inside_the_figure(figures, labels):
    """The study's figures place their axes with margins in inches, not tight_layout (its cost: issue 16);
    rotated tick labels as long as the study's (its merges' labels, the frame personas' names), titles and
    axis labels must still lie inside the figure. Figure 6.5 is drawn with every persona's name."""
    from types import SimpleNamespace

    from pairplay.core.personas import PERSONAS
    n = len(labels)
    keys = list(PERSONAS)
    info = SimpleNamespace(speech=0.5, head=0.25, facial=True, gaze=False)
    plots.profiles(keys, {k: p.name for k, p in PERSONAS.items()}, [info] * len(keys), [(1, 2, 3, 4)] * len(keys),
                   plots.Path("profiles.png"), [info] * len(keys), 50)
    plots.comparison_bars(labels, {"a": np.full(n, 20.0), "b": np.full(n, 25.0)}, plots.Path("evaluation.png"),
                          PICKS_UNIT, "a title")
    plots.grouped_bars_with_spread(labels, {"x": np.full((3, n), 20.0)}, [18.0] * n, plots.Path("merges.png"), "t")
    plots.frame_calibration(labels, {"x": np.full((3, n), 20.0)}, [1, 2], np.full((n, 2), 0.9),
                            plots.Path("frames.png"), 3, 200)
    for name, fig in figures.items():
        fig.canvas.draw()  # places the axis labels beside the tick labels
        renderer = fig.canvas.get_renderer()
        box = fig.bbox
        texts = [t for ax in fig.axes for t in (*_drawn_tick_labels(ax), ax.title, ax.xaxis.label, ax.yaxis.label)
                 if t.get_text() and t.get_visible()]
        for t in texts:
            extent = t.get_window_extent(renderer)
            assert extent.x0 >= box.x0 - 1 and extent.y0 >= box.y0 - 1, (name, t.get_text())
            assert extent.x1 <= box.x1 + 1 and extent.y1 <= box.y1 + 1, (name, t.get_text())

"""`pairplay bench`'s verdicts: one goals table, met / missed / context, --check, the README table."""

import datetime

import pytest

from pairplay.bench.goals import GOALS, verdict
from pairplay.cli import bench


def row(goal=None, value=1.0, ratio=None, **kw):
    return dict(row="r", value=value, unit="s", reference="ref", reference_value=1.0, ratio=ratio, goal=goal, **kw)


def test_a_row_is_judged_on_its_value_or_its_ratio():
    assert verdict(row("study_warm", value=4.9)) == "met" and verdict(row("study_warm", value=5.1)) == "missed"
    assert verdict(row("recorder", ratio=0.95)) == "met" and verdict(row("recorder", ratio=0.85)) == "missed"
    assert verdict(row("recorder", ratio=0.95, failed=True)) == "missed"  # e.g. events lost
    assert verdict(row(None)) == "context"
    assert verdict(row("latency_p50", ratio=None)) == "missed"  # nothing measured is no success


def test_every_bench_source_names_goals_from_the_table():
    import ast
    from pathlib import Path
    root = Path(bench.__file__).resolve().parents[1] / "bench"
    named = set()
    for path in root.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.keyword) and node.arg == "goal" and isinstance(node.value, ast.Constant):
                named.add(node.value.value)
            if isinstance(node, ast.Dict):  # a row written as a dict: "goal" is a key of the table or a name
                for k, v in zip(node.keys, node.values):
                    if isinstance(k, ast.Constant) and k.value == "goal":
                        assert isinstance(v, (ast.Constant, ast.Name)), f"{path.name}:{v.lineno}: goal is not a key"
                        if isinstance(v, ast.Constant):
                            named.add(v.value)
    assert named and named <= set(GOALS)


def test_runs_merge_into_ranges_with_the_verdict_of_the_median(capsys):
    runs = [[row("study_warm", value=v)] for v in (4.0, 6.0, 4.5)]
    merged = bench.merge_runs(runs)
    assert merged[0]["verdict"] == "met" and merged[0]["value"] == 4.5
    assert "4.00 s - 6.00 s" in bench.table(merged)


def test_check_exits_non_zero_on_a_missed_goal(monkeypatch, tmp_path, capsys):
    import types
    fake = types.SimpleNamespace(bench_rows=lambda quick: [row("oracle", value=0.7), row(None)])
    monkeypatch.setitem(bench.SOURCES, "fake", "fake_bench_source")
    monkeypatch.setitem(__import__("sys").modules, "fake_bench_source", fake)
    args = types.SimpleNamespace(only="fake", quick=True, runs=1, json=False, check=True, readme=None)
    assert bench.run(args) == 1
    assert "missed" in capsys.readouterr().out
    args.check = False
    assert bench.run(args) == 0


def test_the_readme_table_is_rewritten_between_its_markers(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n{bench.README_START}\nold\n{bench.README_END}\n\nafter\n")
    text = bench.markdown([row("oracle", value=0.4)], 3, datetime.datetime(2026, 1, 2, 3, 4), [(1.5, 1, 1), (2.5, 1, 1)])
    bench.write_readme(readme, text)
    out = readme.read_text()
    assert "old" not in out and out.endswith("after\n") and "2026-01-02 03:04 UTC" in out
    assert "load average 1.5-2.5" in out and "| met |" in out
    (tmp_path / "NO.md").write_text("no markers")
    with pytest.raises(ValueError):
        bench.write_readme(tmp_path / "NO.md", text)


def test_recorder_cpu_row_measures_the_recorders_writing_thread_beside_the_bare_writer():
    from pairplay.bench.bus import recorder_cpu_rows
    (row,) = recorder_cpu_rows(300, repeats=1)
    assert row["value"] > 0 and row["reference_value"] > 0 and row["ratio"] == pytest.approx(row["value"] / row["reference_value"])


def test_a_source_whose_optional_library_is_not_installed_is_a_row_not_a_traceback(monkeypatch, capsys):
    """The quick start's install has no playwright (the [test] extra): `bench --quick` ended in
    ModuleNotFoundError after 70 s and printed no row. Now the lab's row says why it was not measured,
    as when Chromium is absent, and any source missing a library is one such row, the others printed."""
    import sys

    from pairplay.cli.main import main

    monkeypatch.setitem(sys.modules, "playwright", None)  # import playwright -> ModuleNotFoundError
    monkeypatch.setitem(sys.modules, "playwright.sync_api", None)
    monkeypatch.setitem(sys.modules, "rerun", None)  # the view's source, imported afresh without it
    monkeypatch.delitem(sys.modules, "pairplay.bench.view", raising=False)
    assert main(["bench", "--quick", "--only", "lab,view"]) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    lab = next(line for line in out.splitlines() if line.startswith("lab:"))
    assert "not measured, playwright is not installed" in lab, out
    view = next(line for line in out.splitlines() if line.startswith("view:"))
    assert "not measured, rerun is not installed" in view, out


def test_quick_mode_times_warm_runs_as_the_full_mode_does(monkeypatch):
    """A new user's trial: `bench --quick` timed one cold run (the games' stream keys hashed inside the
    timing, ~20 us a game and role: 8,192 for the batch of 2,048): agent steps/s 0.7-2.2 M/s, "missed",
    where the full bench measured 6-7 M/s. Now the timed run (the last: repeats 1) hashes no key; the
    one before it, untimed, did."""
    from pairplay.bench import core
    from pairplay.core.rng import _key_row

    hashed, real = [], core.run_games

    def run_games(*args, **kwargs):  # the real games, each call's new keys written down
        before = _key_row.cache_info().misses
        result = real(*args, **kwargs)
        hashed.append(_key_row.cache_info().misses - before)
        return result
    monkeypatch.setattr(core, "run_games", run_games)
    _key_row.cache_clear()
    core.simulator_rate(2048, 20, repeats=1)  # bench_rows(quick=True)'s batch
    assert hashed[0] == 2048 and hashed[-1] == 0, hashed


def test_the_steps_rows_hold_one_result_at_a_time(monkeypatch):
    """The batch of 2,048 measured 1.7-1.9 M/s where it plays 6-8 M/s: simulator_rate kept every run's
    result, so each run faulted in 50 MiB of fresh memory (huge pages the kernel compacted for, as system
    time inside the CPU timing). No run's Q-table may be alive when the next run starts."""
    import weakref
    from pairplay.bench import core

    alive, real = [], core.run_games

    def run_games(*args, **kwargs):  # the real games; how many earlier results live on, written down
        alive.append(sum(ref() is not None for ref in refs))
        result = real(*args, **kwargs)
        refs.append(weakref.ref(result.q))
        return result
    refs: list = []
    monkeypatch.setattr(core, "run_games", run_games)
    core.simulator_rate(64, 5, repeats=3)
    assert alive == [0, 0, 0, 0], alive


def test_the_scaling_rows_base_is_a_warm_run(monkeypatch):
    """A new user's trial: the scaling rows' base (8 x 10 games x 500 rounds) was the first training of the
    process, cold, so the rows beside it always said "met". Every timed training now follows an untimed
    one of the same size."""
    from pairplay.bench import core

    calls, real = [], core.train

    def train(personas, games, rounds, seed):  # the real training, each call written down
        calls.append((games, rounds))
        return real(personas, games, rounds, seed)
    monkeypatch.setattr(core, "train", train)
    core.scaling_rows(1)
    assert calls == [(10, 500), (10, 500), (100, 500), (100, 500), (10, 2000), (10, 2000)]


def _one_source(monkeypatch, measured: list):
    """The bench with one source of one row (the real sources take minutes), each measuring written down."""
    import sys
    import types

    def rows(quick):
        measured.append(quick)
        return [row("oracle", value=0.4)]
    monkeypatch.setattr(bench, "SOURCES", {"fake": "fake_bench_source"})
    monkeypatch.setitem(sys.modules, "fake_bench_source", types.SimpleNamespace(bench_rows=rows))


@pytest.mark.parametrize("text,extra,said", [
    ("# no markers\n", [], "has no <!-- bench:start --> ... <!-- bench:end --> section"),
    (f"{bench.README_END}\nold\n{bench.README_START}\n", [], "has no <!-- bench:start -->"),
    (b"\xff\xfe binary", [], "not UTF-8 text"),
    (f"{bench.README_START}\nold\n{bench.README_END}\n", ["--quick"], "--quick would replace it with part of one"),
])
def test_a_readme_that_cannot_take_this_runs_table_is_refused_before_measuring(monkeypatch, tmp_path, capsys,
                                                                               text, extra, said):
    """A new user's trial: a --readme without the bench markers was refused only after all the measuring
    (minutes), a binary one was a traceback after it, and `--quick --only lspi --readme` replaced the
    README's whole 35-row table with LSPI's 4 quick rows. Now the README, and a run whose table may replace
    its own (every source, full size), are checked first: one line, exit 2, nothing measured or written."""
    from pairplay.cli.main import main

    measured = []
    _one_source(monkeypatch, measured)
    readme = tmp_path / "R2.md"
    readme.write_bytes(text if isinstance(text, bytes) else text.encode())
    before = readme.read_bytes()
    assert main(["bench", "--readme", str(readme), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and "Traceback" not in err, err
    assert measured == [] and readme.read_bytes() == before and sorted(tmp_path.iterdir()) == [readme]


def test_readme_with_only_part_of_the_sources_is_refused(monkeypatch, tmp_path, capsys):
    """`bench --only lspi --readme README.md` replaced the README's whole table with LSPI's rows."""
    import sys
    import types

    from pairplay.cli.main import main

    measured = []
    _one_source(monkeypatch, measured)
    monkeypatch.setitem(bench.SOURCES, "other", "other_bench_source")
    monkeypatch.setitem(sys.modules, "other_bench_source", types.SimpleNamespace(bench_rows=lambda quick: []))
    readme = tmp_path / "README.md"
    readme.write_text(f"{bench.README_START}\nold\n{bench.README_END}\n")
    assert main(["bench", "--only", "fake", "--readme", str(readme)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--only would replace it with part of one" in err and "--readme" in err, err
    assert measured == [] and "old" in readme.read_text()


def test_the_readme_table_names_the_command_that_ran(monkeypatch, tmp_path, capsys):
    """Before: the header said "Generated by `pairplay bench --runs 1 --readme README.md`" whatever ran."""
    from pairplay.cli.main import main

    measured = []
    _one_source(monkeypatch, measured)
    readme = tmp_path / "my readme.md"
    readme.write_text(f"# x\n{bench.README_START}\nold\n{bench.README_END}\nafter\n")
    assert main(["bench", "--runs", "2", "--readme", str(readme)]) == 0
    text = readme.read_text()
    assert measured == [False, False] and "old" not in text and text.endswith(f"{bench.README_END}\nafter\n")
    assert f"Generated by `pairplay bench --runs 2 --readme '{readme}'` on " in text, text


def test_the_scaling_rows_time_cpu_not_the_schedulers_wall(monkeypatch):
    """At load 13 the scaling rows' wall-time ratios were 1.12-1.28x ("missed") where the same runs' CPU time
    was 1.00-1.01x: the wall measured the shared machine. Every timing of the rows is the process's CPU time."""
    import time
    from pairplay.bench import core

    clocks, real = [], core.warm_then_best

    def timed(run, repeats, clock=time.perf_counter):
        clocks.append(clock)
        return real(lambda: None, repeats, clock)
    monkeypatch.setattr(core, "warm_then_best", timed)
    core.scaling_rows(1)
    assert clocks == [time.process_time] * 3, clocks

"""`pairplay sweep`: a grid of study settings x seeds, resumable, the same tables locally and on Dask."""

import contextlib
import http.server
import json
import shutil
import signal
import socketserver
import threading
import time
from pathlib import Path

import pytest

from pairplay.errors import OptionError, escaped
from pairplay.report.sweep import Cell, GridError, finished_cells, read_grid, run_sweep, summarise, write_sweep

GRID = """
seeds = 2
[study]
personas = "blind"
games = 1
rounds = 20
eval_rounds = 5
[grid]
reward_bonus = ["correct", "consistent"]
"""


def _grid(tmp_path: Path, text: str = GRID) -> Path:
    path = tmp_path / "grid.toml"
    path.write_text(text)
    return path


def _tables(out: Path) -> tuple[str, str]:
    return (out / "sweep.csv").read_text(), (out / "cells.csv").read_text()


ONE_SEED = GRID.replace("seeds = 2", "seeds = 1")


@pytest.fixture(scope="module")
def one_seed(tmp_path_factory):
    """One finished sweep of ONE_SEED (2 settings x 1 seed) by the verb, made once: the tests that start from
    a finished sweep copy it (finished_copy) and change their own copy (each paid a sweep and its figures).
    Returns its folder and what the verb said while it computed the cells (not -q)."""
    import contextlib
    import io

    from pairplay.cli.main import main

    folder = tmp_path_factory.mktemp("one_seed")
    said = io.StringIO()
    with contextlib.redirect_stdout(said):
        assert main(["sweep", str(_grid(folder, ONE_SEED)), "--out", str(folder / "out")]) == 0
    return folder, said.getvalue()


def finished_copy(one_seed, tmp_path: Path, out: str = "out") -> tuple[Path, Path]:
    """(grid.toml, out folder) in tmp_path: a copy of one_seed's finished sweep, its files' times kept."""
    folder, _ = one_seed
    shutil.copy2(folder / "grid.toml", tmp_path / "grid.toml")
    shutil.copytree(folder / "out", tmp_path / out)
    return tmp_path / "grid.toml", tmp_path / out


@pytest.fixture(scope="module")
def two_seeds(tmp_path_factory):
    """GRID (2 settings x 2 seeds) swept locally and summarised, once: the resume and the Dask cluster start
    from it (each computed the same four cells). Returns (folder, grid, the first run)."""
    folder = tmp_path_factory.mktemp("two_seeds")
    grid = read_grid(_grid(folder))
    first = run_sweep(grid, folder / "out")
    write_sweep(folder / "out", grid, finished_cells(folder / "out", grid), first)
    return folder, grid, first


def test_a_sweep_writes_every_cell_and_resumes_without_recomputing(two_seeds, tmp_path):
    folder, grid, first = two_seeds
    assert len(grid.cells()) == 4 and len({c.id for c in grid.cells()}) == 4
    assert (first.cells, first.computed) == (4, 4)
    shutil.copytree(folder / "out", tmp_path / "out")
    before = _tables(tmp_path / "out")
    victim = grid.cells()[1]
    (tmp_path / "out" / "cells" / f"{victim.id}.json").unlink()  # as if interrupted before that cell
    again = run_sweep(grid, tmp_path / "out")
    assert again.computed == 1
    write_sweep(tmp_path / "out", grid, finished_cells(tmp_path / "out", grid), again)
    assert _tables(tmp_path / "out") == before  # each cell is reproducible by its seed
    rows = summarise(grid, finished_cells(tmp_path / "out", grid))
    ratio = [r for r in rows if r["measure"] == "all/ratio"]
    assert len(ratio) == 2 and all(r["n"] == 2 and r["ci95_low"] <= r["mean"] <= r["ci95_high"] for r in ratio)
    assert (tmp_path / "out" / "figures" / "all-ratio.png").stat().st_size > 0


def test_a_dask_cluster_of_two_workers_gives_the_same_tables(two_seeds, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    folder, grid, _ = two_seeds  # the same grid swept locally
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        remote = run_sweep(grid, tmp_path / "dask", scheduler=cluster.scheduler_address)
        worker = next(iter(cluster.workers.values())).worker_address  # a worker's port given for the scheduler's:
        with pytest.raises(OptionError, match="a Dask Worker, not a scheduler"):  # a TypeError's traceback
            run_sweep(grid, tmp_path / "dask", scheduler=worker)
    assert remote.computed == 4 and remote.where.startswith("dask tcp://127.0.0.1:")
    write_sweep(tmp_path / "dask", grid, finished_cells(tmp_path / "dask", grid), remote)
    assert _tables(tmp_path / "dask") == _tables(folder / "out")


def test_a_cluster_with_no_worker_is_said_and_ends_in_one_line_naming_the_cells_kept(tmp_path, capsys, monkeypatch):
    """A trial: `pairplay sweep --scheduler` at a scheduler with no worker (none started; or its only worker
    killed 3 s into the sweep) printed nothing for 10 minutes, waiting on cells nobody would run. Now a
    sweep says once that the cluster has no worker, and after NO_WORKER_S with none ends in one line naming
    --scheduler and the cells kept, exit 2; a sweep whose worker was lost after a cell keeps that cell."""
    distributed = pytest.importorskip("dask.distributed")
    from pairplay.cli.main import main
    from pairplay.report import sweep

    monkeypatch.setattr(sweep, "NO_WORKER_S", 1.0)
    monkeypatch.setattr(sweep, "WORKER_POLL_S", 0.2)
    grid = _grid(tmp_path)
    with distributed.LocalCluster(n_workers=0, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        none = tmp_path / "no\tne"  # a path said escaped, as every line says it (trial32 D)
        assert main(["sweep", str(grid), "--out", str(none), "--scheduler", address, "-q"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 2, err  # the wait said once, then the line that ends it
        assert f"has no worker to run the cells; waiting up to 1 s for one (`dask worker {address}` starts one)" in err
        # trial32 D: "0 of 4 cells finished, kept in <out>/cells" of a folder removed on the way out
        assert ("has had no worker for 1 s; 0 of 4 cells finished (none kept): start a worker "
                f"(`dask worker {address}`) and run the same command again (--scheduler {address})") in err, err
        assert not none.exists()  # nothing kept: nothing it made stays

        # a worker that does one cell and is then lost: the cell is kept, the same command resumes
        cluster.scale(1)
        cluster.wait_for_workers(1)
        real_store = sweep._write_json_atomic

        def store_then_lose_the_worker(path, data):
            real_store(path, data)
            if len(list(path.parent.glob("*.json"))) == 1:
                cluster.scale(0)
        monkeypatch.setattr(sweep, "_write_json_atomic", store_then_lose_the_worker)
        lost = tmp_path / "lo\nst"
        assert main(["sweep", str(grid), "--out", str(lost), "--scheduler", address, "-q"]) == 2
        err = capsys.readouterr().err
        kept = len(list((lost / "cells").glob("*.json")))
        assert 1 <= kept < 4 and f"{kept} of 4 cells finished, kept in {escaped(lost / 'cells')}: " in err, err
        assert "the same command resumes from them" in err and err.count("\n") == 2, err


@pytest.mark.parametrize("text,needle", [
    ("seeds = 0", "seeds = 0"),
    ("seeds = 1_000_000", "seeds = 1_000_000: 1 setting x 1000000 seeds"),  # as typed, not 1000000
    ("seeds = [1, 0x1]", r"seeds: repeats a seed \(0x1\)"),
    ("seed = 3", r"seed: no such key at the top of the file \(did you mean `seeds`\?\)"),  # "unknown key\(s\)"
    ("[grid]\npsi = 0.5", r"\[grid\] psi: must be a non-empty list of values, got 0.5"),
    ("[grid]\nwobble = [1, 2]", r"\[grid\] wobble: no study setting `wobble`; known: algorithm, "),
    # a misspelt setting: the one it resembles (it was "unknown study setting 'rouns'", no table)
    ("[study]\nrouns = 20", r"\[study\] rouns: no study setting `rouns` \(did you mean `rounds`\?\)"),
    # a value as typed (`rounds = 20.0`, `1_0`), where it came from: the table and key
    ("[study]\nrounds = 20.0", r"\[study\] rounds: must be an integer, got 20.0$"),
    ("[grid]\nrounds = [20, 1_0, -1_0]", r"\[grid\] rounds = -1_0: must be at least 1, got -1_0 \(cell rounds = -1_0\)"),
    ("[grid]\ngames = [1, 1]", r"\[grid\] games: repeats a value \(1\)"),
    ("[grid]\ngames = ['two']", "must be an integer, got 'two'"),
    ("[study]\npersonas = 'nobody'", "nobody"),
    ("reuse = true\n[study]\npersonas = 'blind'", "at least 2 personas"),
    ("[study]\ngames = 2\n[grid]\ngames = [1, 2]", r"\[grid\] games: both fixed in \[study\] and swept in \[grid\]"),
    ("grid = [", "not TOML"),
    ("[study]\npersonas = ['blind', '']", "each item of the list is one persona's name"),
    ("[study]\npersonas = ['blind', 3]", r"\[study\] personas: must be text, got \['blind', 3\]"),
    ("[grid]\npersonas = [['blind', 'blind']]", "names blind twice"),
    # the same personas in another order: the same cells (a trial: both computed, identical rows)
    ("[grid]\npersonas = [['blind', 'deaf'], ['deaf', 'blind']]",
     r"\[grid\] personas: repeats a value \(\['deaf', 'blind'\] = \['blind', 'deaf'\]: the same personas in another order"),
    ("[grid]\npersonas = ['blind,deaf', 'deaf, Blind']", r"repeats a value \('deaf, Blind' = 'blind,deaf': the same personas"),
])
def test_a_grid_that_cannot_run_is_refused_naming_the_file_and_key(tmp_path, text, needle):
    with pytest.raises(GridError, match=needle) as info:
        read_grid(_grid(tmp_path, text))
    assert str(tmp_path / "grid.toml") in str(info.value)


def test_the_order_of_personas_changes_no_measure_so_a_grid_takes_one_order():
    """Why the grid refuses `personas = [["blind","deaf"], ["deaf","blind"]]`: each persona's games are seeded
    by its key (core/study.py train) and each measure named by it, so another order gives the same numbers,
    the policy-reuse experiment's too."""
    from pairplay.report.study import StudySettings
    from pairplay.report.sweep import cell_measures

    def measures(personas: str) -> dict:
        return cell_measures(StudySettings(personas=personas, games=2, rounds=30, eval_rounds=5, seed=3,
                                           reuse_last=10), reuse=True)

    forward, backward = measures("blind,deaf,vincent"), measures("vincent,deaf,blind")
    assert forward.keys() == backward.keys()
    # all/ratio is a mean of the personas' ratios: summed in another order it may differ in its last bit
    assert forward == {k: pytest.approx(v, rel=1e-12, abs=0) for k, v in backward.items()}


def test_personas_may_be_a_toml_list_the_same_sweep_as_the_string(tmp_path):
    """`personas = ["ashley", "helmut"]` was refused ("is not a str"): a researcher writes a list in TOML.
    A list is the names it holds, fixed or as a grid value: the same settings and cells as the string."""
    as_text = read_grid(_grid(tmp_path, 'seeds = 1\n[study]\npersonas = "ashley,helmut"\n'
                                        '[grid]\nrounds = [20]\n'))
    as_list = read_grid(_grid(tmp_path, 'seeds = 1\n[study]\npersonas = ["ashley", "helmut"]\n'
                                        '[grid]\nrounds = [20]\n'))
    assert as_list == as_text and [c.id for c in as_list.cells()] == [c.id for c in as_text.cells()]
    axis = read_grid(_grid(tmp_path, 'seeds = 1\n[grid]\npersonas = [["blind", "deaf"], "blind", ["deaf"]]\n'))
    assert axis.axes == {"personas": ["blind,deaf", "blind", "deaf"]}
    assert [s.persona_list()[0].key for s in map(axis.study_settings, axis.cells())] == ["blind", "blind", "deaf"]


def test_the_verb_refuses_another_grids_folder_in_one_line(tmp_path, pairplay_cli):
    out = tmp_path / "out"
    out.mkdir()
    (out / "grid.toml").write_text("seeds = 1\n")
    run = pairplay_cli("sweep", _grid(tmp_path), "--out", out, "--quiet")
    assert run.returncode == 2 and "another grid" in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert Cell((), 0).id != Cell((), 1).id


def test_a_personas_axis_draws_each_personas_measures_over_the_settings_that_train_it(tmp_path):
    """A persona's measures exist only where it is trained: the figure of `learned/blind` has the
    settings with blind in them, not every setting of the grid (examples/sweep-50.toml's shape)."""
    grid = read_grid(_grid(tmp_path, GRID.replace('personas = "blind"\n', "").replace(
        'reward_bonus = ["correct", "consistent"]', 'personas = ["blind", "deaf", "blind,deaf"]')))
    run = run_sweep(grid, tmp_path / "out")
    written = write_sweep(tmp_path / "out", grid, finished_cells(tmp_path / "out", grid), run)
    rows = summarise(grid, finished_cells(tmp_path / "out", grid))
    blind = [r["personas"] for r in rows if r["measure"].startswith("blind/")]
    assert blind and set(blind) == {"blind", "blind,deaf"}
    assert all(p.stat().st_size > 0 for p in written)
    assert any(p.name.startswith("blind-") for p in written)


def test_a_sweep_over_the_learner_runs_lspi_and_refuses_lspi_settings_that_cannot_run(tmp_path):
    from pairplay.report.sweep import cell_measures

    grid = read_grid(_grid(tmp_path, GRID.replace('reward_bonus = ["correct", "consistent"]',
                                                   'algorithm = ["q-learning", "lspi"]').replace("seeds = 2", "seeds = 1")))
    q, lspi = (cell_measures(grid.study_settings(c)) for c in grid.cells())
    assert q["blind/first50"] != lspi["blind/first50"]  # the learner is not silently Q-learning
    for bad in ('algorithm = ["sarsa"]', 'algorithm = ["lspi"]\nlspi_every = [0]'):
        with pytest.raises(GridError, match="algorithm|improve_every"):
            read_grid(_grid(tmp_path, GRID.replace('reward_bonus = ["correct", "consistent"]', bad)))


def test_a_resume_with_nothing_to_do_writes_nothing_and_says_so(one_seed, tmp_path, capsys):
    """Run again on a finished sweep, the verb rewrote sweep.md ("computed 0 in 0.0 s"), losing what the run
    that did the work said. Now nothing is written, and one line says there was nothing to do."""
    from pairplay.cli.main import main

    assert "2 computed" in one_seed[1]  # the run that did the work (not -q: it silences these lines)
    grid, out = finished_copy(one_seed, tmp_path)
    before = {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.rglob("*") if p.is_file()}
    assert main(["sweep", str(grid), "--out", str(out)]) == 0  # not -q: it silences these lines
    said = capsys.readouterr().out.splitlines()
    assert said == [f"nothing to do: all 2 cells (2 settings x 1 seed) were finished; {out / 'sweep.md'} is as it was"]
    assert {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.rglob("*") if p.is_file()} == before
    (out / "sweep.md").unlink()  # the summary not written (a run stopped after its cells): written, 0 computed
    assert main(["sweep", str(grid), "--out", str(out)]) == 0  # not -q: it silences these lines
    assert "written again (missing or unreadable): sweep.md;" in capsys.readouterr().out
    assert "computed 0" in (out / "sweep.md").read_text()


def test_force_writes_the_summary_again_and_a_resume_writes_what_is_missing_or_unreadable(one_seed, tmp_path,
                                                                                          capsys):
    """Before (a new user's trial): `sweep g.toml --out sw --force` on a finished sweep said "nothing to do" and
    left a junk sweep.md and a deleted figure missing, though a folder's --force replaces the files it writes
    there; without --force a deleted figure stayed missing too. Now --force writes the summary again from the
    cells (which stay), and a resume writes again only what is missing or unreadable, the rest as it was."""
    from pairplay.cli.main import main

    grid, out = finished_copy(one_seed, tmp_path)
    cells = {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in (out / "cells").iterdir()}
    good_md = (out / "sweep.md").read_bytes()
    (out / "sweep.md").write_text("junk")
    (out / "figures" / "all-ratio.png").unlink()
    assert main(["sweep", str(grid), "--out", str(out), "--force", "-q"]) == 0
    assert (out / "sweep.md").read_bytes().startswith(b"# pairplay sweep\n")
    assert (out / "figures" / "all-ratio.png").read_bytes().startswith(b"\x89PNG")
    assert {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in (out / "cells").iterdir()} == cells
    capsys.readouterr()

    (out / "sweep.md").write_bytes(good_md)  # as the run that did the work wrote it: kept
    (out / "figures" / "all-ratio.png").unlink()
    (out / "cells.csv").write_bytes(b"\xff\xfe junk")
    kept = {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.rglob("*")
            if p.is_file() and p.name not in ("cells.csv", "all-ratio.png", ".pairplay-sweep.manifest")}
    assert main(["sweep", str(grid), "--out", str(out)]) == 0
    said = capsys.readouterr().out.splitlines()
    assert said == ["all 2 cells (2 settings x 1 seed) were finished; written again (missing or unreadable): "
                    f"cells.csv, figures/all-ratio.png; the rest is as it was; {out / 'sweep.md'}"], said
    assert (out / "figures" / "all-ratio.png").read_bytes().startswith(b"\x89PNG")
    assert (out / "cells.csv").read_text().startswith("cell,reward_bonus,seed,measure,value")
    assert {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in kept} == kept
    assert main(["sweep", str(grid), "--out", str(out)]) == 0  # now whole: nothing to do
    assert capsys.readouterr().out.startswith("nothing to do: ")


def test_a_summary_interrupted_part_way_leaves_the_earlier_one_whole(one_seed, tmp_path, monkeypatch):
    """Before: sweep.csv, cells.csv, the figures and sweep.md were replaced one by one, so a Ctrl-C while the
    figures were drawn left a new sweep.csv beside the earlier sweep.md. Now the summary is written beside the
    folder and moved in as a whole (outputs.output_folder); the cells and grid.toml stay as they are."""
    from pairplay.report import plots

    grid_file, out = finished_copy(one_seed, tmp_path)  # a finished sweep (it paid a sweep and a summary here)
    grid = read_grid(grid_file)
    run = run_sweep(grid, out)
    assert run.computed == 0
    for name in ("sweep.csv", "cells.csv", "sweep.md"):
        (out / name).write_text("earlier run")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(plots, "sweep_measure", ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        write_sweep(out, grid, finished_cells(out, grid), run)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no staging folder left


def test_a_scheduler_that_does_not_answer_is_one_line_naming_the_option(tmp_path, capsys, monkeypatch):
    """Before (a new user's trial): 'pairplay sweep: Timed out trying to connect to tcp://... after 10 s',
    which did not say it was --scheduler's address."""
    import socket

    from pairplay.cli.main import main
    from pairplay.report import sweep
    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1)  # the 10 s of a lab's network are not needed here
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    grid = tmp_path / "g.toml"
    grid.write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 1\neval_rounds = 1\n')
    assert main(["sweep", str(grid), "--out", str(tmp_path / "o"), "--scheduler", f"tcp://127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--scheduler" in err and f"127.0.0.1:{port}" in err, err


def _closed_port() -> int:
    import socket
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("address,said", [
    ("tcp://127.0.0.1:{closed}", "nothing listens at that address (connection refused)"),
    ("ws://127.0.0.1:{closed}", "nothing listens at that address (connection refused)"),
    ("tcp://127.0.0.1:99999", "not a Dask address (port 99999 is not 1..65535)"),
    ("tcp://:8786", "not a Dask address (no host before :8786)"),
    ("tcp://localhost", "not a Dask address (HOST:PORT expected after tcp://, got 'localhost')"),
    ("inproc://x", "sweep reaches a scheduler over tcp:// or ws://, not inproc://"),
    ("ucx://127.0.0.1:1", "not ucx://"),
    ("tls://127.0.0.1:1", "not tls://"),
    ("tcp://no-such-host.invalid:8786", "the host no-such-host.invalid is not known"),
])
def test_a_scheduler_that_cannot_be_reached_is_one_line_in_our_words_at_once(tmp_path, capsys, address, said):
    """A trial: a refused connection took Dask's whole 10 s (its connect retries until its timeout), and Dask's
    texts came through ("(OSError: Timed out trying to connect ...)", "(ValueError: not enough values to unpack",
    "(TypeError: Can't instantiate abstract class UCXConnector", "TLS expects a `ssl_context` argument"). Each
    is one line saying what, naming --scheduler and the address, exit 2, well within the 10 s."""
    from pairplay.cli.main import main
    address = address.format(closed=_closed_port())
    grid = tmp_path / "g.toml"
    grid.write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 1\neval_rounds = 1\n')
    start = time.monotonic()
    code = main(["sweep", str(grid), "--out", str(tmp_path / "o"), "--scheduler", address])
    took = time.monotonic() - start
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and said in err and f"(--scheduler {address})" in err, err
    assert "Error" not in err and "Timed out" not in err and "expects" not in err, err
    assert took < 5, took  # importing Dask's modules, not its 10 s
    assert not (tmp_path / "o").exists()


def _no_measures(d):
    d["measures"] = {}


def _one_measure_less(d):
    del d["measures"]["blind/last50"]


def _text_measure(d):
    d["measures"]["blind/learned"] = "20.8"


def _nan_measure(d):
    d["measures"]["all/ratio"] = float("nan")


def _another_seed(d):
    d["seed"] += 100


def _misspelt_key(d):
    d["measure"] = {}  # a key CellFile does not declare: said in the file's words (schemas/jsonfile.py in_words)


DAMAGES = [
    (_text_measure, "measure(s) not a finite number: blind/learned = '20.8'"),
    (_nan_measure, "measure(s) not a finite number: all/ratio = nan"),
    (_no_measures, "lacks measure(s) all/ratio, blind/first50"),
    (_one_measure_less, "lacks measure(s) blind/last50"),
    (_another_seed, "holds another cell's setting or seed"),
    ("{", "not a cell file"),
    (_misspelt_key, "not a cell file: no key `measure` is known here (did you mean `measures`?)"),
    ("", "the file is empty"),
]


def test_a_cell_file_that_cannot_be_used_is_computed_again_and_said(tmp_path, capsys):
    """A new user's trial: a cell whose measure was text ended the summary in a traceback; one of `"measures":
    {}` counted as finished and the summary said n = 1 where the seeds were 2, without a word (a NaN alike);
    a file that was not JSON was computed again without a word. Every cell file is checked whole when read
    (CellFile, its measures those of the cell); one that cannot be used is computed again and a line names it.
    The tables are those of the undamaged sweep.
    One finished sweep of one setting x 8 seeds, each cell file damaged in one of DAMAGES' ways, and one resume:
    each damage is in a file of its own and said in a line of its own (each case paid a sweep and a summary)."""
    from pairplay.cli.main import main

    grid, out = _grid(tmp_path, GRID.replace('["correct", "consistent"]', '["correct"]').replace(
        "seeds = 2", f"seeds = {len(DAMAGES)}")), tmp_path / "out"
    assert main(["sweep", str(grid), "--out", str(out), "-q"]) == 0  # a finished sweep of that grid
    before = _tables(out)
    victims = sorted((out / "cells").glob("*.json"))
    assert len(victims) == len(DAMAGES)
    for victim, (damage, _) in zip(victims, DAMAGES):
        if isinstance(damage, str):
            victim.write_text(damage)
        else:
            data = json.loads(victim.read_text())
            damage(data)
            victim.write_text(json.dumps(data))
    (out / "sweep.md").unlink()  # as a sweep stopped before its summary
    capsys.readouterr()
    assert main(["sweep", str(grid), "--out", str(out)]) == 0
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == len(DAMAGES), captured.err
    for victim, (_, said) in zip(victims, DAMAGES):
        [line] = [x for x in lines if x.startswith(f"WARNING pairplay.sweep: {victim}: ")]
        assert line.startswith(f"WARNING pairplay.sweep: {victim}: {said}"), line
        assert line.endswith(": computing the cell again"), line
    assert f"{len(DAMAGES)} computed" in captured.out, captured
    assert _tables(out) == before


def test_the_measures_a_cell_file_must_hold_are_those_a_cell_gives(tmp_path):
    """`measure_names` (what a cell file is checked against) and `cell_measures` (what a cell computes) agree,
    with the reuse experiment and without."""
    from pairplay.report.sweep import cell_measures, measure_names
    for reuse in (False, True):
        grid = read_grid(_grid(tmp_path, f'seeds = 1\nreuse = {str(reuse).lower()}\n[study]\npersonas = "blind,deaf"\n'
                                         'games = 1\nrounds = 10\neval_rounds = 2\n'))
        settings = grid.study_settings(grid.cells()[0])
        assert set(cell_measures(settings, reuse)) == measure_names(settings, reuse)


class _Hung(BaseException):
    """The test's own deadline passed (a BaseException: no handler of the verb's takes it for its own)."""


@contextlib.contextmanager
def _server(reply: bytes | None):
    """A TCP service on loopback that is no Dask scheduler: it sends `reply` on each connection, or,
    with None, is `http.server`'s, which waits for a request line Dask never sends."""
    if reply is None:
        class Quiet(http.server.SimpleHTTPRequestHandler):
            def log_message(self, *args):  # its log goes to stderr, where the verb's one line is looked for
                pass
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    else:
        class Banner(socketserver.BaseRequestHandler):
            def handle(self):
                try:
                    self.request.sendall(reply)
                    self.request.recv(1024)  # the other side's bytes, then close
                except ConnectionResetError:  # the check's first connection (is anything listening?) closes
                    pass  # unread: socketserver's traceback of it went to the stderr the verb's line is read from
        server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Banner)
    server.daemon_threads = True
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


@pytest.mark.parametrize("service,said", [
    ("nonsense", "not a Dask address"),
    ("tcp://127.0.0.1", "not a Dask address"),
    ("foo://127.0.0.1:1", "not a Dask address"),
    (b"SSH-2.0-OpenSSH_9.6\r\n" * 4, "not a Dask scheduler answered"),
    (None, "no Dask scheduler answered within 1 s"),
])
def test_a_scheduler_address_where_no_scheduler_is_one_line_within_the_timeout(tmp_path, capsys, monkeypatch,
                                                                                service, said):
    """A new user's trial: `--scheduler nonsense` was a ValueError's traceback (exit 1); a port whose service
    sends bytes first (an SSH banner) said "out of memory (... ulimit -v ...)" (Dask read them as a frame's
    length and asked for 3 EiB); one of `python3 -m http.server` hung over 300 s (Dask's timeout covers the
    connect, not its handshake). Each is one line naming the option and the address, exit 2, in the timeout,
    and nothing is written."""
    from pairplay.cli.main import main
    from pairplay.report import sweep
    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1)
    grid = tmp_path / "g.toml"
    grid.write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 1\neval_rounds = 1\n')

    def hung(*_):
        raise _Hung
    before = signal.signal(signal.SIGALRM, hung)
    try:
        with _server(service) if isinstance(service, bytes) or service is None else \
                contextlib.nullcontext(service) as address:
            start = time.monotonic()
            signal.setitimer(signal.ITIMER_REAL, 20)
            try:
                code = main(["sweep", str(grid), "--out", str(tmp_path / "o"), "--scheduler", address])
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            took = time.monotonic() - start
    finally:
        signal.signal(signal.SIGALRM, before)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and said in err, err
    assert "--scheduler" in err and address in err and "memory" not in err, err
    assert took < 1 + 3, took  # the timeout, and what importing Dask takes
    assert not (tmp_path / "o").exists()


def test_the_scheduler_check_says_the_same_from_a_running_event_loop():
    """run_sweep called in a notebook (an event loop running): the probe's asyncio.run was refused there, and
    the line said "RuntimeError: asyncio.run() cannot be called from a running event loop" of any address."""
    import asyncio

    from pairplay.report.sweep import check_scheduler

    async def in_a_loop(address):
        check_scheduler(address)
    with _server(b"SSH-2.0-OpenSSH_9.6\r\n" * 4) as address:
        with pytest.raises(OptionError, match="bytes that are no Dask message"):
            asyncio.run(in_a_loop(address))


def test_the_default_folder_says_sweep_once(tmp_path, monkeypatch):
    """Before (a new user's trial): examples/sweep-psi.toml wrote out/sweep-sweep-psi."""
    from pairplay.cli.main import main
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sweep-tiny.toml").write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 1\n'
                                              'eval_rounds = 1\n')
    assert main(["sweep", "sweep-tiny.toml", "-q"]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["sweep-tiny"]


def test_workers_that_together_would_pass_the_memory_limit_are_refused_before_anything_is_written(tmp_path, capsys):
    """Each cell was checked against core/simulate.py MEMORY_LIMIT alone: `--workers N` ran N such cells side
    by side (N x 2 GB). Two cells of about 1.2 GB each on two workers are refused, naming --workers."""
    from pairplay.cli.main import main
    from pairplay.processes import max_workers
    if max_workers() < 2:
        pytest.skip("one CPU: --workers 2 is refused by its own bound")
    grid = tmp_path / "big.toml"
    grid.write_text('seeds = 2\n\n[study]\npersonas = "ashley"\ngames = 2500\nrounds = 500\n\n[grid]\n'
                    'reward_bonus = ["correct"]\n')
    out = tmp_path / "sweep"
    try:
        code = main(["sweep", str(grid), "--workers", "2", "--out", str(out)])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--workers" in err and "over the 2.0 GB allowed" in err, err
    assert not out.exists()


@pytest.mark.parametrize("text,said", [
    # a new user's trial: a top-level key written below a table's line is that table's
    ("[study]\npersonas = 'blind'\nseeds = 3\n", "[study] seeds: `seeds` belongs at the top of the file, not to "
     "[study]: the keys after a [study] line are that table's; move `seeds = ...` above that line"),
    ("[grid]\npsi = [0.5]\nreuse = true\n", "[grid] reuse: `reuse` belongs at the top of the file, not to [grid]"),
    # a trial: a study setting above the [study] or [grid] line (it was "unknown key(s) psi")
    ("seeds = 2\npsi = 0.5\n[grid]\nrounds = [10, 20]\n", "psi: `psi` belongs to [study] or [grid], not at the top "
     "of the file (above its first [table] line): move `psi = ...` below the [study] or [grid] line"),
    ("rounds = 10\n[study]\npsi = 0.5\n", "rounds: `rounds` belongs to [study] or [grid], not at the top of the file"),
    ("[grid.psi]\nx = [1]\n", "[grid.psi]: [grid.psi] is a table, where `psi` takes a value: write `psi = ...` "
     "among the keys of [grid]"),
    ("[study.psi]\nx = 1\n", "[study.psi]: [study.psi] is a table, where `psi` takes a value"),
    ("[seeds]\nn = 1\n", "[seeds]: [seeds] is a table, where `seeds` takes a value: write `seeds = ...` at the top"),
    ("study = 3\n", "study: a value where a table is expected: write a [study] line, its keys below it"),  # a traceback
])
def test_a_key_or_table_at_the_wrong_level_says_where_it_belongs(tmp_path, text, said):
    (tmp_path / "g.toml").write_text(text)
    with pytest.raises(GridError) as info:
        read_grid(tmp_path / "g.toml")
    assert str(info.value) == f"{tmp_path / 'g.toml'}: {said}" or said in str(info.value), info.value


def test_sweep_md_says_what_first50_and_last50_average_in_short_cells(tmp_path):
    """A trial: a 40-round sweep's first50 and last50 were both all 40 rounds, one value under two names,
    and nothing said so. sweep.md states each short cell's windows."""
    grid = read_grid(_grid(tmp_path, GRID.replace("rounds = 20\n", "").replace(
        'reward_bonus = ["correct", "consistent"]', "rounds = [20, 60]").replace("seeds = 2", "seeds = 1")))
    run = run_sweep(grid, tmp_path / "out")
    write_sweep(tmp_path / "out", grid, finished_cells(tmp_path / "out", grid), run)
    md = (tmp_path / "out" / "sweep.md").read_text()
    assert ("first50 and last50 average the first and last 50 training rounds, fewer in a shorter cell: "
            "rounds = 20: the first and last 20 of 20 (both all of them: one value); "
            "rounds = 60: the first and last 50 of 60.") in md, md


def test_an_interval_of_picks_per_round_stops_at_18_a_perfect_round(tmp_path):
    """A trial's sweep.md said `blind/learned 12.976 to 28.224`: the t-interval of a mean of 2 seeds went below
    18 picks per round, which no round can take (18 = perfect). Every picks-per-round measure's interval is
    clipped at 18, in sweep.csv, sweep.md and the figures; a ratio (learned / oracle) at 0, its own floor."""
    from pairplay.report.sweep import SweepRun

    grid = read_grid(_grid(tmp_path))
    per_seed = [{"blind/learned": 19.0, "blind/oracle": 18.2, "blind/first50": 19.0, "blind/last50": 18.5,
                 "blind/ratio": 0.5, "all/ratio": 0.5},
                {"blind/learned": 22.2, "blind/oracle": 21.0, "blind/first50": 30.0, "blind/last50": 25.0,
                 "blind/ratio": 1.5, "all/ratio": 1.5}]
    results = {Cell(setting, seed).id: per_seed[k] for setting in grid.settings() for k, seed in enumerate(grid.seeds)}
    rows = summarise(grid, results)
    picks = [r for r in rows if r["measure"].split("/")[-1] in ("learned", "oracle", "first50", "last50")]
    assert len(picks) == 8 and all(r["ci95_low"] == 18.0 and r["ci95_high"] > r["mean"] for r in picks), picks
    ratio = [r for r in rows if r["measure"].endswith("ratio")]
    assert ratio and all(r["ci95_low"] == 0.0 < r["mean"] for r in ratio)  # a ratio's floor is 0, not 18
    write_sweep(tmp_path / "out", grid, results, SweepRun(4, 4, 0.1, "this process"))
    md = (tmp_path / "out" / "sweep.md").read_text()
    assert "| blind/learned | 2 | 20.600 | 2.263 | 18.000 to 40.930 |" in md, md
    low = [line.split(",")[-2] for line in (tmp_path / "out" / "sweep.csv").read_text().splitlines()
           if "/learned" in line]
    assert low == ["18.000000"] * 2


def test_a_scheduler_without_dasks_distributed_installed_is_one_line(monkeypatch):
    """A new user's trial: on a plain install (no `cluster` extra) `sweep --scheduler` was a ModuleNotFoundError
    traceback."""
    import sys

    from pairplay.errors import OptionError
    from pairplay.report.sweep import check_scheduler
    monkeypatch.setitem(sys.modules, "distributed.comm", None)  # as if not installed: its import fails
    with pytest.raises(OptionError, match=r"needs Dask's distributed package: pip install -e '\.\[cluster\]'"):
        check_scheduler("tcp://127.0.0.1:1")


def test_a_forced_sweep_of_another_grid_keeps_none_of_the_first_grids_figures(one_seed, tmp_path):
    """A trial: `sweep A --out D`, then `sweep B --out D --force` (another grid: other personas): the figures of
    A's measures stayed in figures/ beside B's, one folder of two sweeps. The summary is written whole each
    time, and what an earlier summary wrote that this one does not (its manifest says which) is removed; the
    folder then holds what a fresh sweep of B writes, and the user's files, one in figures/ too."""
    from pairplay.cli.main import main

    def files(folder):
        return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())

    other = tmp_path / "other.toml"
    other.write_text(ONE_SEED.replace('"blind"', '"deaf"').replace(
        'reward_bonus = ["correct", "consistent"]', 'reward_bonus = ["correct"]'))
    _, out = finished_copy(one_seed, tmp_path, "D")  # `sweep A --out D`, finished
    fresh = tmp_path / "fresh"
    assert "figures/blind-ratio.png" in files(out)
    (out / "notes.txt").write_text("the user's")
    (out / "figures" / "mine.png").write_bytes(b"the user's")
    assert main(["sweep", str(other), "--out", str(out), "--quiet", "--force"]) == 0
    assert main(["sweep", str(other), "--out", str(fresh), "--quiet"]) == 0
    assert files(out) == sorted(files(fresh) + ["figures/mine.png", "notes.txt"]), files(out)


@pytest.mark.parametrize("line,said", [
    ("rounds = 1e7", "[study] rounds: must be an integer, got 1e7"),  # it was "rounds = 10000000.0 is not an integer"
    ("psi = 1e7", "[study] psi = 1e7: must be between 0 and 1, got 1e7"),  # "psi = 10000000: ..., got 10000000"
    ("psi = 1.50", "[study] psi = 1.50: must be between 0 and 1, got 1.50"),
])
def test_a_number_of_the_sweep_file_is_echoed_as_the_file_has_it(tmp_path, line, said):
    """A trial: a refused number was echoed as Python parsed it, not as written; the line points at the file's
    text (pairplay/numbers.py typed_floats)."""
    (tmp_path / "g.toml").write_text(f'seeds = 1\n[study]\npersonas = "blind"\n{line}\n')
    with pytest.raises(GridError) as info:
        read_grid(tmp_path / "g.toml")
    assert str(info.value) == f"{tmp_path / 'g.toml'}: {said}", info.value


def test_a_comment_in_the_grid_file_is_the_same_grid_and_another_grid_keeps_the_users_cell_files(one_seed,
                                                                                                tmp_path):
    """A trial: only a `# comment` added to the grid file made "the sweep of another grid" (exit 2), and with
    --force every finished cell (the same cells) was thrown away; a forced sweep of another grid removed every
    cells/*.json, a user's file there too, and then any file named like a cell. Grids are compared as read; only
    cell files a sweep wrote (a cell named by its own id) are removed."""
    from pairplay.cli.main import main

    one = ONE_SEED
    first, out = finished_copy(one_seed, tmp_path, "D")  # `sweep grid.toml --out D`, finished
    cells = sorted(p.name for p in (out / "cells").glob("*.json"))
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "cells").glob("*.json")}
    first.write_text("# the same grid, with a note\n" + one)
    assert main(["sweep", str(first), "--out", str(out), "--quiet"]) == 0  # a resume: nothing to compute
    assert {p.name: p.stat().st_mtime_ns for p in (out / "cells").glob("*.json")} == stamps
    (out / "cells" / "mine.json").write_text("{}")
    mine = "0" * 20 + ".json"  # named like a cell (a cell id), but no sweep wrote it: it was removed
    (out / "cells" / mine).write_text('{"the user\'s": "notes"}')
    other = tmp_path / "other.toml"
    other.write_text(one.replace('"blind"', '"deaf"'))
    assert main(["sweep", str(other), "--out", str(out), "--quiet"]) == 2  # another grid: refused
    assert main(["sweep", str(other), "--out", str(out), "--quiet", "--force"]) == 0
    left = sorted(p.name for p in (out / "cells").glob("*.json"))
    assert left == sorted([*cells, "mine.json", mine]), left  # (a cell's id digests its axes and seed: the same names)
    assert all((out / "cells" / name).stat().st_mtime_ns != stamps[name] for name in cells)  # computed again


def test_a_table_inside_another_is_told_to_stand_as_its_own_table(tmp_path):
    """A trial: `[study.grid]` was told "move `grid = ...` above that line", a key's advice for a table."""
    (tmp_path / "g.toml").write_text('seeds = 1\n[study]\npersonas = "blind"\n[study.grid]\npsi = [0.1, 0.2]\n')
    with pytest.raises(GridError) as info:
        read_grid(tmp_path / "g.toml")
    assert "write it as its own [grid] table, not inside [study]" in str(info.value), info.value
    assert "grid = ..." not in str(info.value)


def test_a_folder_at_the_sweeps_grid_copy_is_named_as_a_folder_with_or_without_force(tmp_path, capsys):
    """A trial: a folder at D/grid.toml was "the sweep of another grid", and with --force the OS's "Is a
    directory"; it is a folder where the sweep writes a file, said so either way, before any work."""
    from pairplay.cli.main import main

    out = tmp_path / "D"
    (out / "grid.toml").mkdir(parents=True)
    for force in ([], ["--force"]):
        assert main(["sweep", str(_grid(tmp_path)), "--out", str(out), "--quiet", *force]) == 2
        err = capsys.readouterr().err.strip()
        assert err.endswith(f"is a folder where a file is written; a folder is never replaced, --force or not: "
                            f"remove or rename it ({out / 'grid.toml'})"), err
    assert not (out / "cells").exists()


def test_a_grid_whose_axes_are_reordered_is_another_grid(tmp_path):
    """A trial: reordered [grid] keys were "the same grid" (dicts compare without order), yet a cell's id digests
    its setting in the grid's key order, so every cell was computed again beside the old ones."""
    from pairplay.cli.sweep import same_grid

    head = 'seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 20\n[grid]\n'
    one = _grid(tmp_path, head + 'reward_bonus = ["correct"]\neval_rounds = [5, 6]\n')
    (tmp_path / "two.toml").write_text("# a note\n" + head + 'reward_bonus = ["correct"]\neval_rounds = [5, 6]\n')
    (tmp_path / "three.toml").write_text(head + 'eval_rounds = [5, 6]\nreward_bonus = ["correct"]\n')
    grid = read_grid(one)
    assert same_grid(tmp_path / "two.toml", grid)
    assert not same_grid(tmp_path / "three.toml", grid)
    assert {c.id for c in read_grid(tmp_path / "three.toml").cells()} != {c.id for c in grid.cells()}

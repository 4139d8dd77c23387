"""Work lost with a worker process or a Dask cluster ends in ONE line, exit 1, saying what happened and what is
kept (pairplay.errors.WorkerLost). Before (a new user's trial): a `sweep --workers 2` worker SIGKILLed (as the
out-of-memory killer does) and a `study` whose figure process was killed ended in BrokenProcessPool's traceback;
a `sweep --scheduler` whose scheduler stopped, in Dask's ERROR traceback and FutureCancelledError's."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from childprocs import children as _children

LONG = """
seeds = 2
[study]
personas = "blind"
games = 1
rounds = {rounds}
eval_rounds = 5
[grid]
reward_bonus = ["correct", "consistent"]
"""


def _spawned(pid: int) -> list[int]:
    """`pid`'s multiprocessing "spawn" children (a pool's workers; not the resource tracker)."""
    kids = []
    for kid in _children(pid):
        try:
            if b"spawn_main" in Path(f"/proc/{kid}/cmdline").read_bytes():
                kids.append(kid)
        except OSError:
            pass
    return kids


def _pairplay(*args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "pairplay", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def _kill_a_worker_once_started(verb: subprocess.Popen) -> None:
    """SIGKILL one of `verb`'s pool workers, as the out-of-memory killer would, once it has one."""
    while verb.poll() is None:
        workers = _spawned(verb.pid)
        if workers:
            time.sleep(1.0)  # it has taken its work
            os.kill(workers[0], signal.SIGKILL)
            return
        time.sleep(0.05)
    pytest.fail(f"it ended before a worker started: {verb.stderr.read()}")


def _one_line(verb: subprocess.Popen) -> str:
    err = verb.stderr.read()
    verb.wait()
    assert verb.returncode == 1, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_a_sweep_whose_pool_worker_is_killed_says_so_in_one_line_and_exits_1(tmp_path):
    (tmp_path / "grid.toml").write_text(LONG.format(rounds=200_000))
    sweep = _pairplay("sweep", "grid.toml", "--workers", "2", "--out", "out", "-q", cwd=tmp_path)
    try:
        _kill_a_worker_once_started(sweep)
        err = _one_line(sweep)
    finally:
        if sweep.poll() is None:
            sweep.kill()
            sweep.wait()
    assert err.startswith("pairplay sweep: a worker process died (killed by signal 9 (SIGKILL"), err
    assert "BrokenProcessPool" not in err
    kept = len(list((tmp_path / "out" / "cells").glob("*.json")))
    if kept:  # the other worker had finished a cell: kept, said, for the same command to resume from
        assert err.rstrip().endswith(f"; {kept} of 4 cells finished, kept in out/cells: the same command resumes "
                                     "from them"), err
    else:  # none finished: nothing it made stays, so the same command runs again into the same --out
        assert "nothing more was written" in err and not (tmp_path / "out").exists(), err


def test_a_study_whose_figure_process_is_killed_says_so_in_one_line_and_writes_nothing(tmp_path):
    study = _pairplay("study", "--out", "out", "--rounds", "3000", "-q", cwd=tmp_path)
    try:
        _kill_a_worker_once_started(study)
        err = _one_line(study)
    finally:
        if study.poll() is None:
            study.kill()
            study.wait()
    assert err.startswith("pairplay study: a worker process died (killed by signal 9 (SIGKILL"), err
    assert err.rstrip().endswith("nothing more was written") and not (tmp_path / "out").exists(), err


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _dask(*args: str, cwd: Path, env: dict | None = None) -> subprocess.Popen:
    dask = Path(sys.executable).with_name("dask")
    return subprocess.Popen([str(dask), *args], cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=env, start_new_session=True)


def _stop(*processes: subprocess.Popen) -> None:
    for p in processes:
        if p.poll() is None:
            p.kill()
            p.wait()


def _wait_for_a_worker(address: str) -> None:
    from dask.distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(1, timeout=60)


def test_a_sweep_whose_dask_scheduler_stops_keeps_its_cells_in_one_line(tmp_path):
    pytest.importorskip("dask.distributed")
    (tmp_path / "grid.toml").write_text(LONG.format(rounds=60_000))
    address = f"tcp://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    scheduler = _dask("scheduler", "--host", "127.0.0.1", "--port", port, "--dashboard-address", "127.0.0.1:0",
                      cwd=tmp_path)
    worker = sweep = None
    try:
        worker = _dask("worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard", cwd=tmp_path)
        _wait_for_a_worker(address)
        sweep = _pairplay("sweep", "grid.toml", "--scheduler", address, "--out", "out", "-q", cwd=tmp_path)
        cells = tmp_path / "out" / "cells"
        while sweep.poll() is None and not list(cells.glob("*.json")):  # one cell finished, three to go
            time.sleep(0.05)
        scheduler.send_signal(signal.SIGKILL)
        err = _one_line(sweep)
    finally:
        _stop(*(p for p in (sweep, worker, scheduler) if p is not None))
    assert err.startswith(f"pairplay sweep: the Dask scheduler at {address} stopped answering (connection lost); "
                          f"1 of 4 cells finished, kept in out/cells: the same command resumes from them"), err
    assert len(list((tmp_path / "out" / "cells").glob("*.json"))) == 1


def test_a_dask_worker_that_cannot_load_pairplay_is_one_line_naming_it_before_any_cell(tmp_path):
    pytest.importorskip("dask.distributed")
    (tmp_path / "grid.toml").write_text(LONG.format(rounds=20))
    broken = tmp_path / "broken" / "pairplay"
    broken.mkdir(parents=True)
    (broken / "__init__.py").write_text("raise ImportError('no pairplay on this worker')\n")
    address = f"tcp://127.0.0.1:{_free_port()}"
    scheduler = _dask("scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                      "--dashboard-address", "127.0.0.1:0", cwd=tmp_path)
    worker = None
    try:
        worker = _dask("worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard", cwd=tmp_path,
                       env={**os.environ, "PYTHONPATH": str(broken.parent)})
        _wait_for_a_worker(address)
        sweep = _pairplay("sweep", "grid.toml", "--scheduler", address, "--out", "out", "-q", cwd=tmp_path)
        err = sweep.stderr.read()
        assert sweep.wait() == 2, err  # the user's setup to fix, as a cluster with no worker (README's exit table)
    finally:
        _stop(*(p for p in (worker, scheduler) if p is not None))
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("pairplay sweep: the Dask worker tcp://127.0.0.1:"), err
    assert "cannot load pairplay (ImportError: no pairplay on this worker): install pairplay " in err, err
    assert err.rstrip().endswith(f"(--scheduler {address})"), err
    assert not (tmp_path / "out").exists()


def _faulty_worker_cluster(tmp_path: Path, fault: str, scheduler_env: dict | None = None):
    """A real `dask scheduler` and one `dask worker` whose cells meet `fault` (a sitecustomize.py on its
    PYTHONPATH replaces report/sweep.py cell_measures in that worker only). Returns (address, processes)."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(
        "import os, signal\nimport pairplay.report.sweep as sweep\n\n"
        f"def cell_measures(settings, reuse=False):\n    {fault}\n\nsweep.cell_measures = cell_measures\n")
    address = f"tcp://127.0.0.1:{_free_port()}"
    scheduler = _dask("scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                      "--dashboard-address", "127.0.0.1:0", cwd=tmp_path, env={**os.environ, **(scheduler_env or {})})
    worker = _dask("worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard", cwd=tmp_path,
                   env={**os.environ, "PYTHONPATH": str(site)})
    return address, (worker, scheduler)


@pytest.mark.parametrize("fault, env, said", [
    ("raise RuntimeError('out of luck')", {},
     "failed on a Dask worker: RuntimeError: out of luck (its traceback is in the worker's log)"),
    # the worker dies under the cell, as the OOM killer's SIGKILL would; the scheduler gives up at once
    ("os.kill(os.getpid(), signal.SIGKILL)", {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0"},
     "killed every Dask worker that ran it (Dask's KilledWorker"),
])
def test_a_cell_that_fails_or_kills_its_dask_worker_is_one_line_naming_the_cell(tmp_path, fault, env, said):
    pytest.importorskip("dask.distributed")
    (tmp_path / "grid.toml").write_text(LONG.format(rounds=20))
    address, processes = _faulty_worker_cluster(tmp_path, fault, env)
    try:
        _wait_for_a_worker(address)
        sweep = _pairplay("sweep", "grid.toml", "--scheduler", address, "--out", "out", "-q", cwd=tmp_path)
        err = _one_line(sweep)
    finally:
        _stop(*processes)
    assert err.startswith("pairplay sweep: cell "), err
    assert "reward_bonus=" in err and said in err, err
    assert err.rstrip().endswith("nothing more was written") and not (tmp_path / "out").exists(), err

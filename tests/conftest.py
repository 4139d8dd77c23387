"""Shared fixtures: one headless Chromium per test process (Debian's /usr/bin/chromium,
driven by Playwright; never `playwright install`).

Rule: what is expensive and read-only is made once per test process (session
scope) and shared; each test still gets its own pages in its own browser
context, so no test sees another's state. Under pytest-xdist each worker is
its own process with its own browser, ports (port 0) and tmp_path.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
from pathlib import Path

import pytest

# A suite started in the background (`cmd &` in a script, nohup) inherits SIGINT ignored, and Python then
# installs no KeyboardInterrupt handler: the tests that deliver a Ctrl-C to themselves or to the commands
# they start (which inherit the ignored signal) failed only when started so. Each test process takes it back.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)



@pytest.fixture(autouse=True)
def _cli_log_handler_left():
    """A verb run in-process (`main([...])`, cli/main.py configure_logging) leaves its root handler writing to the
    stderr of its time: pytest's capture of that test, closed after it. A later test's log line then went to a
    closed stream, and logging printed "--- Logging error ---" with the test's source on the real stderr (a
    stderr assertion of tests/test_lab_log_bursts failed so in the full run). Removed after each test."""
    yield
    cli = sys.modules.get("pairplay.cli.main")
    if cli is not None and cli._handler is not None:
        logging.getLogger().removeHandler(cli._handler)
        cli._handler = None


CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions"]


@pytest.fixture(scope="session")
def browser():
    """A headless Chromium for the whole test process (a launch costs 1-3 s on a loaded 2-core
    machine). Locally it is skipped, with the reason, only when Debian's chromium is absent;
    in CI (CI=true) that is a failure."""
    if not CHROMIUM.exists():
        message = f"{CHROMIUM} is absent: `apt-get install chromium` (Debian's; browsers are not downloaded)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture(scope="session")
def pairplay_cli():
    """`pairplay_cli(*args, cwd=None, timeout=120)` -> subprocess.CompletedProcess of `python -m pairplay
    ARGS` (text stdout and stderr), each a process of its own forked from one that imported pairplay
    once per test process (tests/cli_zygote.py `shared`, which also forks the long-running commands a test
    talks to: `shared().start`): for tests of what a command does, not of how a process starts or stops
    (signals, Ctrl-C, start-up and exit timing keep their own `python -m pairplay`). pairplay's import
    printing anything fails the first test that uses it."""
    from cli_zygote import shared

    zygote = shared()

    def run(*args, cwd=None, timeout=120):
        return zygote.run([str(a) for a in args], Path(cwd or os.getcwd()), timeout=timeout)

    return run


def pytest_xdist_auto_num_workers(config) -> int:
    """`-n auto` (pyproject's addopts): three workers on CI's two cores, as many tests wait on
    sockets, child processes and the browser (a two-worker run used 1.3 cores on average: 523 s of CPU
    in 403 s; 2026-12-01, 1,881 tests on this 2-core VM, warm numba cache: two workers ~330 s, three
    292 s). None for a run that selects the slow tests (soaks and
    fault runs time themselves and make machine-wide network namespaces). PAIRPLAY_TEST_WORKERS=N
    sets the number (0: everything in the main process, as `-n 0` does)."""
    if os.environ.get("PAIRPLAY_TEST_WORKERS", "").isdecimal():
        return int(os.environ["PAIRPLAY_TEST_WORKERS"])
    marks = config.getoption("markexpr", "") or ""
    return 0 if "slow" in marks.replace("not slow", "") else 3


# Files whose tests take the longest, longest first (summed test time, setups included, of a full run on 3 workers,
# 2026-12-03 07:19 UTC, main ce43397, at load 6-12 from other suites: 1,734 s; test_sweep 141 s, test_protocol 140 s,
# test_cli_mistakes 87 s, test_recorder_gone 62 s; every file of 5 s or more): with whole files per worker
# (--dist loadfile) the files go out in this order, so that the run ends on short files and no worker is left alone
# with a long one. The list of 2026-12-02 lacked test_recorder_gone, test_cut_signals (56 s), test_start_order_heads
# (41 s), test_worker_lost (34 s) and test_protocol_cut_game/_reinvalid (30 s each), which then went out in
# alphabetical order after every listed file: replaying that run's test times through xdist's loadfile scheduling
# (a worker takes its next file when 2 of its tests are left), the last worker ended at 597.6 s with the old list,
# 579.5 s with this one, against 577.9 s (a third of the sum) for a perfect split, and 639.0 s in alphabetical order.
# Measure again when a file's time changes much (a run's --junitxml, its test times summed by file).
# pytest-xdist >= 3.5 sorts the files by their NUMBER of tests (test_cli_mistakes' 189 rows first, test_study_batch's
# 3 late), which ignored this list; pytest_configure turns that off where xdist lets it (3.8's
# --no-loadscope-reorder; an option in addopts would be refused by 3.5-3.7, which pyproject allows).
# test_study_batch stays first: it compiles the numba kernels into their cache before the files
# that start many processes (the controller warms them too: pytest_configure) and is the longest single test.
LONGEST_FIRST = ("test_study_batch.py", "test_sweep.py", "test_protocol.py", "test_cli_mistakes.py",
                 "test_recorder_gone.py", "test_cut_signals.py", "test_start_order_heads.py", "test_session_end.py",
                 "test_outputs.py", "test_protocol_interrupted.py", "test_worker_lost.py",
                 "test_recorder_restart.py", "test_protocol_cut_game.py", "test_protocol_reinvalid.py",
                 "test_study_cli.py", "test_faults.py", "test_console_browser.py", "test_lab_browser.py",
                 "test_mcap_damage.py", "test_cli_signals.py", "test_cli_full_disk.py", "test_faults_restart.py",
                 "test_cli_logging.py", "test_console_live.py", "test_faults_signals.py", "test_combine_place.py",
                 "test_study_guard.py", "test_lab_heartbeat.py", "test_session_readback.py",
                 "test_processes_orphan.py", "test_cli_out_of_threads.py", "test_chunk_bomb.py",
                 "test_counterfactual.py", "test_robot_iristk.py", "test_journal.py", "test_session_crash.py",
                 "test_robot_realtime.py", "test_slow_requests.py", "test_deletion_withholds.py", "test_copies.py",
                 "test_refusal.py", "test_lines_escaped.py", "test_session_robot.py", "test_input_kinds.py",
                 "test_view_rerun.py", "test_protocol_threads.py", "test_faults_startup.py",
                 "test_protocol_signals.py", "test_board_live.py", "test_recorder_holes.py",
                 "test_cli_environment.py", "test_output_locks.py", "test_recording_tampered.py",
                 "test_python_api.py", "test_journal_left.py", "test_router.py", "test_protocol_journal_wait.py",
                 "test_zenoh_log.py", "test_security.py", "test_view_cli.py", "test_output_kinds.py",
                 "test_console_layout.py", "test_replay_late_tail.py", "test_study_recovered.py",
                 "test_session_force_left.py", "test_forge.py", "test_cli_zygote.py", "test_output_writers.py",
                 "test_recorder_foreign_journal.py", "test_start_signals.py", "test_verify_stopped.py",
                 "test_ids_never_twice.py", "test_docs.py", "test_session_cli.py", "test_session_ids.py",
                 "test_bus_direct.py", "test_robot_virtual.py", "test_study_folder_lock_outputs.py")


def pytest_configure(config) -> None:
    """Files go out to the workers in LONGEST_FIRST's order, not by their number of tests. The controller of
    an xdist run compiles the numba kernels into their on-disk cache once, before the workers start: in a
    fresh clone each of the three workers (and the commands they start) compiled them at the same moment on
    two cores (a fresh clone's suite 337 s against 292 s with the cache warm)."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput") \
            and not config.option.collectonly:
        from pairplay.core import kernels
        kernels.warm_up()


def pytest_collection_modifyitems(items) -> None:
    """The files in LONGEST_FIRST first, in that order; the rest after, in their own order
    (a stable sort: the order within each file is kept; every worker collects the same)."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))

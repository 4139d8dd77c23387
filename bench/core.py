"""Benchmarks of the compiled core, each beside a reference measured in the same run.

Rule: the machine's limit for an agent step is a compiled bare bandit loop
(epsilon-greedy Q-learning on a 23 x 88 table, SplitMix64 draws, no game), so
the simulator's steps/s and the study's wall time are given beside it; the
study runs in fresh processes (warm: the kernels in numba's cache; first run:
an empty cache, compile included) and its output is checked against the
pinned digests (tests/data/study_digests.json, when the repository is there).
Timings are the best of `repeats` (the machine is shared: the best is the
least disturbed), each after one run untimed (`warm_then_best`): `--quick`
(repeats 1) times warm runs as the full bench does, only fewer and smaller,
so its verdicts judge the same thing; goals live in bench/goals.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numba import njit

from pairplay.core import kernels, threads
from pairplay.core.personas import PERSONAS
from pairplay.core.rng import game_seed
from pairplay.core.simulate import run_games
from pairplay.core.study import train

PINNED = Path(__file__).resolve().parents[1] / "tests" / "data" / "study_digests.json"
MIB = 1024 * 1024


@njit(cache=True)
def _bandit(q, steps, key):
    """Epsilon-greedy Q-learning on a bandit: 4 SplitMix64 draws, an argmax over 88 and an update per step."""
    for i in range(steps):
        base = np.uint64(4 * i)
        s = np.int64(kernels.draw(key, base) * q.shape[0])
        if kernels.draw(key, base + np.uint64(1)) < 0.1:
            a = np.int64(kernels.draw(key, base + np.uint64(2)) * q.shape[1])
        else:
            a = np.argmax(q[s])
        q[s, a] += 0.1 * (kernels.draw(key, base + np.uint64(3)) - q[s, a])
    return q


def warm_then_best(run, repeats: int, clock=time.perf_counter) -> float:
    """The least time `run()` took over `repeats` calls, after one call untimed: the first call of a
    process pays what the later ones do not (kernels loaded from numba's cache, the games' stream
    keys hashed, ~20 us a game and role, then cached). `bench --quick` timed that first call alone
    (repeats 1): its agent steps/s were 0.7-2.2 M/s where the full bench measured 6-7 M/s, and the
    scaling rows' base was cold, so they always said "met"; now quick and full time the same warm runs."""
    run()
    best = float("inf")
    for _ in range(repeats):
        t = clock()
        run()
        best = min(best, clock() - t)
    return best


def bandit_rate(steps: int, repeats: int = 3) -> float:
    """Steps/s of the compiled bare bandit loop on one core: CPU time, best of `repeats`."""
    q = np.zeros((23, 88))
    _bandit(q, 10, np.uint64(1))
    best = float("inf")
    for r in range(repeats):
        t = time.process_time()
        _bandit(q, steps, np.uint64(r + 1))
        best = min(best, time.process_time() - t)
    return steps / best


def simulator_rate(games: int, rounds: int, repeats: int = 3, workers: int = 1,
                   cpu: bool = True) -> tuple[float, int]:
    """(agent steps/s, steps) of the full simulator, `games` games of Q-learning in one batch (best of `repeats`),
    on `workers` threads (core/threads.py; the goal is per core, so 1 by default).

    An agent step is one suggestion (a turn: two picks, the user, the learner,
    the reward, the update). Stream keys are hashed once per seed and cached,
    so the untimed first run (`warm_then_best`) pays that and the timed ones do not. `cpu`:
    the process's CPU time (all its threads: with one worker, the rate per core
    whatever else the shared machine runs), else the wall time (several workers).

    Each run's result is dropped before the next, as a caller of batches does. Holding all of them
    (4 x 50 MiB of Q-tables and counts at 2,048 games) made every run fault in fresh memory: numpy
    asks for transparent huge pages on arrays of 4 MiB and more, and with the kernel's THP defrag
    "madvise" the faulting thread compacts memory itself; 0.25-0.30 s of system time a run on this
    12-hour-old machine, so the batch of 2,048 measured 1.7-1.9 M/s where it plays 6-8 M/s.
    """
    personas = list(PERSONAS.values())
    chosen = [personas[i % len(personas)] for i in range(games)]
    seeds = [game_seed(0, p.key, i) for i, p in enumerate(chosen)]
    steps = [0]

    def run() -> None:
        with threads.at_most(workers):
            steps[0] = int(run_games(chosen, seeds, rounds).picks.sum()) // 2
    best = warm_then_best(run, repeats, time.process_time if cpu else time.perf_counter)
    return steps[0] / best, steps[0]


# ru_maxrss survives fork and exec on Linux (a child started by a big bench process reports the
# bench's size): a process's own peak is its VmHWM.
_PEAK = """
def peak():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
"""

_STUDY = _PEAK + """
import json, resource, sys, time
t0 = time.perf_counter()
from pairplay.core import simulate, study, oracle
steps = [0]
def counted(fn):
    def run(*a, **k):
        r = fn(*a, **k)
        steps[0] += int(r.picks.sum()) // 2
        return r
    return run
study.run_games = oracle.run_games = counted(simulate.run_games)
from pairplay.report.study import StudySettings, output_digests, run_study
report = run_study(StudySettings(seed=0), sys.argv[1])
wall = time.perf_counter() - t0
print(json.dumps({"wall": wall, "timings": report.timings, "steps": steps[0], "rss": peak(),
                  "figures_rss": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024,
                  "digests": output_digests(report.out)}))
"""

_FLOOR = _PEAK + """
import numpy, numba
from pairplay.core import kernels, threads
kernels.warm_up()
print(peak())
"""


# Every child `_python` starts: SIGTERM is its Ctrl-C (the study's interruption path stops and reaps its figure
# worker: report/study.py _Figures), and multiprocessing's resource tracker, if it started one, is ended and reaped
# before it exits (pairplay/processes.py stop_resource_tracker). Imported only when used: the floor's child measures
# a process that imports numpy and numba alone.
_CHILD = """
import atexit, signal, sys
def _stopped(signum, frame):
    raise KeyboardInterrupt
signal.signal(signal.SIGTERM, _stopped)
@atexit.register
def _tracker_reaped():
    if "multiprocessing.resource_tracker" in sys.modules:
        from pairplay.processes import stop_resource_tracker
        stop_resource_tracker()
"""
CHILD_STOP_S = 2.0  # what an interrupted bench gives its child to stop before it is killed


def _python(code: str, *args: str, env: dict | None = None) -> tuple[str, float]:
    """Run `code` in a fresh Python; its stdout and wall time. Interrupted (the bench's Ctrl-C, SIGTERM, SIGHUP),
    the child is stopped and reaped before this raises, its own children with it: before (trial32 I), subprocess.run
    killed it with SIGKILL and returned unwaited, and its study's figure worker outlived the bench by 1.5-2 s."""
    t = time.perf_counter()
    with subprocess.Popen([sys.executable, "-c", _CHILD + code, *args], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, env=env or os.environ.copy()) as proc:
        try:
            out, err = proc.communicate()
        except BaseException:
            _stopped(proc)
            raise
    if proc.returncode:
        raise subprocess.CalledProcessError(proc.returncode, proc.args, out, err)
    return out, time.perf_counter() - t


def _stopped(proc: subprocess.Popen) -> None:
    """SIGTERM (`_CHILD`: its Ctrl-C), waited for CHILD_STOP_S; then SIGKILL. Reaped either way (a child that
    ended by itself as the signal came has its status read by `poll`)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(CHILD_STOP_S)
        except subprocess.TimeoutExpired:
            pass
        finally:  # not ended in time, or a second signal cut the wait
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def study_run(cache_dir: str | None = None) -> dict:
    """`pairplay study` (seed 0, defaults) in a fresh process; with `cache_dir`, numba's cache there."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    with tempfile.TemporaryDirectory() as tmp:
        out, wall = _python(_STUDY, str(Path(tmp) / "study"), env=env)
    result = json.loads(out.strip().splitlines()[-1])
    result["process_wall"] = wall  # interpreter start and imports included
    return result


def study_rows(bandit: float) -> list[dict]:
    warm = [study_run()]
    best = min(warm, key=lambda r: r["process_wall"])
    with tempfile.TemporaryDirectory() as cache:
        first = study_run(cache)
    floor = int(_python(_FLOOR)[0].strip())
    pinned = json.loads(PINNED.read_text())["full"]["seeds"]["0"] if PINNED.exists() else None
    same = [r["digests"] == pinned for r in warm + [first]] if pinned is not None else []
    compile_s = next((v for k, v in first["timings"].items() if k.startswith("kernels")), None)
    rows = [
        dict(row="study end to end, warm (seed 0, 8 personas x 10 games x 500 rounds, all phases, figures)",
             value=best["process_wall"], unit="s", goal="study_warm",
             reference=f"its {best['steps'] / 1e6:.1f} M agent steps at the bare bandit loop's rate",
             reference_value=best["steps"] / bandit, ratio=best["process_wall"] / (best["steps"] / bandit)),
        dict(row=f"study end to end, first run of a fresh install (compile {compile_s:.1f} s included)",
             value=first["process_wall"], unit="s", goal="study_first", reference="the warm study, same run",
             reference_value=best["process_wall"], ratio=first["process_wall"] / best["process_wall"]),
        dict(row="study peak memory (the study process's VmHWM; the figure process beside it: at most "
                 f"{best['figures_rss'] / MIB:.0f} MiB)", value=best["rss"] / MIB, unit="MiB", goal="study_memory",
             reference="a process that only imports numpy and numba and loads the kernels (matplotlib is "
                       "the figure process's)",
             reference_value=floor / MIB, ratio=best["rss"] / floor),
    ]
    if pinned is not None:
        rows.append(dict(row=f"study output byte-identical to the pinned digests (seed 0, {len(same)} runs)",
                         value=float(all(same)), unit="", goal="study_bytes",
                         failed=not all(same), reference=f"{len(pinned)} files pinned", reference_value=None, ratio=None))
    return rows


def oracle_rows(repeats: int) -> list[dict]:
    from pairplay.core.oracle import USER_ALONE, oracle_policies
    personas = list(PERSONAS.values())
    games = [p for p in personas for _ in range(20)]
    seeds = [game_seed(0, "oracle:" + p.key, i) for p in personas for i in range(20)]
    best = warm_then_best(lambda: oracle_policies(personas, 20, 0, 200), repeats)

    def situations() -> None:  # its two iterations' situation games, without the expectation
        for _ in range(2):
            run_games(games, seeds, 200, mode="fixed", policy=np.tile(USER_ALONE, (len(games), 1)))
    ref = warm_then_best(situations, repeats)
    return [dict(row="oracle, all 8 personas (2 iterations x 20 games x 200 rounds)", value=best, unit="s",
                 goal="oracle", reference="its situation games alone", reference_value=ref, ratio=best / ref)]


def scaling_rows(repeats: int) -> list[dict]:
    """Training 10x the games, and 4x the rounds, against that multiple of the base (8 x 10 games x 500
    rounds), each the best of `repeats` warm runs. The base takes ~0.04 s, so one run of it alone was
    noise: 0.84-1.03x in the full bench, and 'missed' by a 1.02x median. The cost is the process's CPU
    time (the study's threads summed): the wall time measured the shared machine's scheduler, at load 13
    1.12-1.28x where the CPU time of the same runs was 1.00-1.01x."""
    personas = list(PERSONAS.values())

    def cpu(games: int, rounds: int) -> float:
        return warm_then_best(lambda: train(personas, games, rounds, 0), repeats, time.process_time)

    base = cpu(10, 500)
    rows = []
    for games, rounds, factor, what in ((100, 500, 10, "10x the games"), (10, 2000, 4, "4x the rounds")):
        w = cpu(games, rounds)
        rows.append(dict(row=f"scaling: training {what} (8 x {games} games x {rounds} rounds, CPU time)", value=w,
                         unit="s",
                         goal="scaling", reference=f"{factor}x the base (8 x 10 x 500: {base:.2f} s), same run",
                         reference_value=factor * base, ratio=w / (factor * base)))
    return rows


def learner_rows(turns: int) -> list[dict]:
    """The learner service's own work per suggestion: request -> SuggestionMade, perception + turn -> reward + update."""
    from pairplay.core.learning import Learner
    from pairplay.core.reward import simulated_reward
    from pairplay.core.rng import UniformStream
    from pairplay.schemas import events as ev
    from pairplay.schemas.envelope import stamped
    from pairplay.schemas.session import SessionConfig
    from pairplay.services.learner import LearnerLogic
    from pairplay.services.node import stream_seed

    config = SessionConfig(session="bench", participant="sim:ashley", persona="ashley", seed=0, rounds=10_000)
    rng = np.random.default_rng(0)
    states, masks = rng.integers(0, 23, turns), rng.integers(1, 1 << 18, turns)

    def e(event, seq):
        return stamped(event, session="bench", source="game", seq=seq, time_ns=seq)

    requests = [e(ev.SuggestionRequested(round=i // 12, turn=i % 12, attempt=0, state=int(states[i]), observed=1,
                                         match=2, covered_mask=int(masks[i]), first=0), 3 * i + 1) for i in range(turns)]
    perceived = [e(ev.SuggestionPerceived(round=i // 12, turn=i % 12, attempt=0, considered=True, consistent=True,
                                          candidate_size=3, candidate_mask=7, second=2), 3 * i + 2) for i in range(turns)]
    resolved = [e(ev.TurnResolved(round=i // 12, turn=i % 12, first=0, second=2, matched=bool(i % 2),
                                  round_over=i % 12 == 11), 3 * i + 3) for i in range(turns)]
    logic = LearnerLogic()
    logic.handle(e(ev.SessionStarted(config=config), 0))
    for i in range(20):  # warm-up: the kernels' first call per process
        logic.handle(requests[i])
        logic.handle(perceived[i])
        logic.handle(resolved[i])
    chunk = max(1, (turns - 20) // 10)  # the best of 10 chunks of turns (the module rule: the least disturbed)
    # "Own work" is the thread's CPU time: on a shared machine the wall time also counts the waits for a
    # core (at load 13 on 2 cores, 4-5x the CPU time); the wall figure is shown beside it.
    ours = ours_wall = float("inf")
    for start in range(20, turns - chunk + 1, chunk):
        t, c = time.perf_counter(), time.thread_time()
        for i in range(start, start + chunk):
            logic.handle(requests[i])
            logic.handle(perceived[i])
            logic.handle(resolved[i])
        ours = min(ours, (time.thread_time() - c) / chunk * 1e6)
        ours_wall = min(ours_wall, (time.perf_counter() - t) / chunk * 1e6)
    learner = Learner(1, UniformStream([stream_seed(config)], "agent"))
    one = np.ones(1, dtype=bool)
    bare = float("inf")
    for start in range(20, turns - chunk + 1, chunk):
        c = time.thread_time()
        for i in range(start, start + chunk):
            r = np.array([i // 12])
            s = states[i:i + 1]
            actions, _ = learner.suggest(s, r)
            reward, learn = simulated_reward(one, one, one, np.array([3]), one)
            learner.learn(s, actions, reward, learn, r)
        bare = min(bare, (time.thread_time() - c) / chunk * 1e6)
    return [dict(row="learner service's own work per live suggestion (request, perception, turn: events out; "
                     f"thread CPU time; wall {ours_wall:.1f} us at load {os.getloadavg()[0]:.1f})",
                 value=ours, unit="us", goal="learner_work",
                 reference="core Learner.suggest + reward + learn alone on arrays, batch of one, CPU",
                 reference_value=bare, ratio=ours / bare)]


def bench_rows(quick: bool = False) -> list[dict]:
    repeats = 1 if quick else 3
    bandit = bandit_rate(2_000_000 if quick else 20_000_000, repeats)
    # Per core: CPU time (at load 13-24 on 2 cores, a wall-clock rate was 0.4-0.5x the CPU rate, the
    # scheduler's share, not the code's); the study rows below are wall time.
    rows = [dict(row="compiled bare bandit loop (23 x 88 Q-learning, 4 draws, argmax, update; CPU time): the limit",
                 value=bandit, unit="steps/s", reference="", reference_value=None, ratio=None)]
    # the steps rows run the full bench's batches in quick mode too (0.2-0.7 M steps, a tenth of a second):
    # the goal is stated for them, and 2,048 games x 4 rounds timed mostly the batch's setup ("missed")
    for games, rounds in ((80, 200), (2048, 20)):
        rate, steps = simulator_rate(games, rounds, repeats)
        rows.append(dict(row=f"agent steps/s, full semantics, batch of {games:,} ({steps / 1e6:.2f} M steps, one "
                             "core, CPU time)",
                         value=rate, unit="steps/s", goal="steps", reference="compiled bare bandit loop, same run",
                         reference_value=bandit, ratio=rate / bandit))
    if threads.WORKERS > 1:  # the same batch on every core the study uses (context: the goal is per core)
        rate, steps = simulator_rate(2048, 20, repeats, threads.WORKERS, cpu=False)
        rows.append(dict(row=f"agent steps/s, batch of 2,048 on {threads.WORKERS} threads (the study's way; "
                             "context)", value=rate, unit="steps/s", reference="compiled bare bandit loop, same run",
                         reference_value=bandit, ratio=rate / bandit))
    rows += oracle_rows(repeats)
    rows += learner_rows(2_000 if quick else 20_000)
    rows += scaling_rows(repeats)  # best of the repeats, as every other timing (one alone: 0.84-1.03x, noise)
    rows += study_rows(bandit)
    return rows

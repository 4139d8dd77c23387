"""Where a pick's way to its suggestion spends its time: the bench's latency row, traced stage by stage.

Rule: runs `pairplay.bench.bus.latency_rows` (the game in this process, the
learner in a `pairplay run learner` process of its own) with timing hooks
wrapped around the shell's steps in both processes: the bus callback
(`Node._on_message`), the service thread taking the message (`Inbox.get`),
the guard (`Guard.check`), the logic (`handle`), numbering (`Driver._stamp`),
encoding and queueing (`Node.publish`) and each put (`Bus.put`,
`Bus.put_batched`, each put also on its own: in the bench only the game's
SuggestionRequested has a subscriber in another process, so its CardRevealed
and CardObserved never reach the wire and the "three puts" are the express
one's), and Python's cyclic collections in either process (`gc.callbacks`).
Times are `time.perf_counter()` (CLOCK_MONOTONIC on Linux: one clock for both
processes). For every first pick that got a suggestion it prints the
p25/p50/p75 of each stage, in microseconds, beside the row's own figures, and
how many picks a collection started during. The hooks cost a few
microseconds per stage: compare stages, not the total with the bench's. A
diagnostic for docs/bus.md, not a bench row.

    .venv/bin/python tools/latency_trace.py [--turns 500]
"""

from __future__ import annotations

import argparse
import atexit
import bisect
import gc
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

TRACE_ENV = "PAIRPLAY_LATENCY_TRACE"  # where a traced process writes its stamps at exit
STAGES = [  # (name, from, to): stamps of one pick's way, in order
    ("bench put -> game callback", "PICK", "cb:CardPicked"),
    ("game callback -> game thread", "cb:CardPicked", "got:CardPicked"),
    ("game guard", "guard0:CardPicked", "guard1:CardPicked"),
    ("game logic", "handle0:CardPicked", "handle1:CardPicked"),
    ("game numbering", "stamp0", "stamp1"),
    ("game: message in -> events out", "got:CardPicked", "decided:CardPicked"),
    ("game encode + queue", "decided:CardPicked", "published"),
    ("game puts (3 events)", "published", "sent"),
    ("  of which CardRevealed (batched)", "pb0:CardRevealed", "pb1:CardRevealed"),
    ("  of which CardObserved (batched)", "pb0:CardObserved", "pb1:CardObserved"),
    ("  of which SuggestionRequested", "put0:SuggestionRequested", "put1:SuggestionRequested"),
    ("SuggestionRequested put -> learner callback", "put0:SuggestionRequested", "L:cb:SuggestionRequested"),
    ("network -> learner callback", "sent", "L:cb:SuggestionRequested"),
    ("learner callback -> learner thread", "L:cb:SuggestionRequested", "L:got:SuggestionRequested"),
    ("learner guard", "L:guard0:SuggestionRequested", "L:guard1:SuggestionRequested"),
    ("learner logic", "L:handle0:SuggestionRequested", "L:handle1:SuggestionRequested"),
    ("learner: message in -> events out", "L:got:SuggestionRequested", "L:decided:SuggestionRequested"),
    ("learner encode + queue", "L:decided:SuggestionRequested", "L:published"),
    ("learner put", "L:published", "L:sent"),
    ("network -> bench", "L:sent", "ARRIVED"),
    ("learner's put -> bench", "L:put0:SuggestionMade", "ARRIVED"),
    ("total", "PICK", "ARRIVED"),
]


def install_hooks(out: str) -> list:
    """Wrap the shell's steps with stamps (see rule); written as JSON to `out` at exit."""
    from pairplay.services import bus, guard, node, runner
    from pairplay.services.game import GameLogic
    from pairplay.services.learner import LearnerLogic
    clock = time.perf_counter
    stamps: list = []  # (what, tag, time)

    def tag_of(key) -> str:
        return key.rsplit("/", 1)[-1] if isinstance(key, str) else ""

    def wrap(cls, name: str, before: str | None, after: str, tag=lambda args, result: ""):
        original = getattr(cls, name)

        def traced(*args, **kwargs):
            if before:
                stamps.append((before, tag(args, None), clock()))
            result = original(*args, **kwargs)
            stamps.append((after, tag(args, result), clock()))
            return result
        setattr(cls, name, traced)
    key_tag = lambda args, _r: tag_of(args[1])  # noqa: E731  (self, key, ...)
    wrap(runner.Node, "_on_message", "cb", "cb_end", key_tag)
    wrap(bus.Inbox, "get", None, "got", lambda _a, r: tag_of(r[0]) if r is not None else "")
    wrap(guard.Guard, "check", "guard0", "guard1", key_tag)
    wrap(node.Driver, "receive", None, "decided", key_tag)
    wrap(node.Driver, "_stamp", "stamp0", "stamp1")
    wrap(runner.Node, "publish", None, "published")
    wrap(bus.Outbox, "publish_here", None, "sent")
    wrap(bus.Bus, "put", "put0", "put1", key_tag)
    wrap(bus.Bus, "put_batched", "pb0", "pb1", key_tag)
    for logic in (GameLogic, LearnerLogic):
        wrap(logic, "handle", "handle0", "handle1", lambda args, _r: type(args[1]).__name__)

    def collected(phase: str, info: dict) -> None:  # a cyclic collection, any thread (gc.callbacks)
        stamps.append(("gc0" if phase == "start" else "gc1", str(info.get("generation")), clock()))
    gc.callbacks.append(collected)

    def dump() -> None:
        with open(out, "w") as f:
            json.dump(stamps, f)
    atexit.register(dump)
    return stamps


def learner_child(argv: list[str]) -> int:
    """`pairplay run learner ...` with the hooks (the bench's learner process)."""
    install_hooks(os.environ[TRACE_ENV])
    from pairplay.cli.main import main
    return main(argv)


def first_after(stamps: list, name: str, start: float, end: float) -> float | None:
    what, _, tag = name.partition(":")
    for w, t, at in stamps:
        if start <= at <= end and w == what and (not tag or t == tag):
            return at
    return None


def collections_in_picks(game: list, learner: list, skip: int = 20) -> dict[str, tuple[int, int, float]]:
    """Per process: (picks a cyclic collection started during, picks, the p50 of those collections in us),
    over first picks that got a suggestion, from the pick's put to the suggestion's arrival."""
    game = sorted(game, key=lambda s: s[2])
    picks = [s[2] for s in game if s[0] == "PICK"]
    arrivals = [s[2] for s in game if s[0] == "ARRIVED"]
    windows = []
    for start, following in zip(picks, picks[1:] + [float("inf")]):
        j = bisect.bisect(arrivals, start)
        if j < len(arrivals) and arrivals[j] < following:
            windows.append((start, arrivals[j]))
    windows = windows[skip:]
    out = {}
    for name, stamps in (("game", game), ("learner", sorted(learner, key=lambda s: s[2]))):
        starts = [s[2] for s in stamps if s[0] == "gc0"]
        ends = [s[2] for s in stamps if s[0] == "gc1"]
        hit, took = set(), []
        for a, b in zip(starts, ends):
            k = bisect.bisect(windows, (a, float("inf"))) - 1
            if k >= 0 and windows[k][0] <= a <= windows[k][1]:
                hit.add(k)
                took.append((b - a) * 1e6)
        out[name] = (len(hit), len(windows), float(np.median(took)) if took else 0.0)
    return out


def stages(game: list, learner: list) -> dict[str, list[float]]:
    """Per stage, its duration (us) for every first pick that got a suggestion."""
    game = sorted(game, key=lambda s: s[2])
    learner = sorted(learner, key=lambda s: s[2])
    picks = [s[2] for s in game if s[0] == "PICK"] + [float("inf")]
    arrivals = [s[2] for s in game if s[0] == "ARRIVED"]
    out: dict[str, list[float]] = {name: [] for name, _, _ in STAGES}
    for start, following in zip(picks, picks[1:]):
        arrived = next((a for a in arrivals if start < a < following), None)
        if arrived is None:
            continue  # a second pick: no suggestion
        at = {"PICK": start, "ARRIVED": arrived}
        for _, *ends in STAGES:
            for name in ends:
                if name not in at:
                    stamps, n = (learner, name[2:]) if name.startswith("L:") else (game, name)
                    # the stage's start must be known for an end "after" it; stamps are in time order
                    at[name] = first_after(stamps, n, start, arrived)
        for stage, a, b in STAGES:
            if at.get(a) is not None and at.get(b) is not None and at[b] >= at[a]:
                out[stage].append((at[b] - at[a]) * 1e6)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--turns", type=int, default=500)
    args = p.parse_args()
    folder = tempfile.mkdtemp(prefix="pairplay-trace-")
    game_out, learner_out = os.path.join(folder, "game.json"), os.path.join(folder, "learner.json")
    stamps = install_hooks(game_out)
    from pairplay.bench import bus as bench_bus
    from pairplay.services.bus import Bus
    clock = time.perf_counter
    put, subscribe, spawn = Bus.put, Bus.subscribe, bench_bus.spawn_module

    def traced_put(self, key, payload):
        if key.endswith("/board/CardPicked"):
            stamps.append(("PICK", "", clock()))
        return put(self, key, payload)

    def traced_subscribe(self, key, callback, *a, **kw):
        if key.endswith("/learner/SuggestionMade"):
            inner = callback

            def callback(k, p):
                stamps.append(("ARRIVED", "", clock()))
                inner(k, p)
        return subscribe(self, key, callback, *a, **kw)

    def traced_spawn(*argv: str):
        if argv[:3] == ("pairplay", "run", "learner"):
            return subprocess.Popen([sys.executable, __file__, "--learner-child", *argv[1:]], stdout=subprocess.PIPE,
                                    env=dict(os.environ, PYTHONUNBUFFERED="1", **{TRACE_ENV: learner_out}))
        return spawn(*argv)
    Bus.put, Bus.subscribe, bench_bus.spawn_module = traced_put, traced_subscribe, traced_spawn
    rows = bench_bus.latency_rows(args.turns)
    with open(learner_out) as f:
        learner = json.load(f)
    print(f"the row (hooked): pick -> suggestion p50 {rows[0]['value']:.0f} us, paced raw round trip "
          f"{rows[0]['reference_value']:.0f} us ({rows[0]['ratio']:.2f}x); the contract's floor {rows[3]['value']:.0f} us")
    print(f"load average {os.getloadavg()[0]:.1f}; per first pick, us:")
    for stage, values in stages(stamps, learner).items():
        if values:
            v = np.percentile(values[20:] or values, [25, 50, 75])
            print(f"  {stage:38s} p25 {v[0]:7.1f}  p50 {v[1]:7.1f}  p75 {v[2]:7.1f}  (n={len(values)})")
    for name, (hit, n, took) in collections_in_picks(stamps, learner).items():
        print(f"  a cyclic collection in the {name}'s process during {hit} of {n} picks (p50 {took:.0f} us each)")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--learner-child":
        sys.exit(learner_child(sys.argv[2:]))
    sys.exit(main())

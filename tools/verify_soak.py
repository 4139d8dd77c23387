"""Verify soak: many real bus sessions, each `pairplay replay --verify`-ed many times (issue 10, item 2).

Rule: 30 sessions over the bus (`pairplay session`, each a subprocess: the
recorder, the services and Zenoh as a user runs them) over the eight personas,
seeds 0-9, game indexes 0-4 and 20 to 250 rounds (ten of 200 or more); each
recording is verified REPEATS times, every verdict must be PASS: the first by
the CLI as a user types it (`pairplay replay REC --verify`), the others by
`verify_recording` in this process (the function the CLI calls; --cli-every 1
makes every one a CLI run, slower by a Python start-up each). Then one recording gets one derived event altered (a
SuggestionMade's action, rewritten into a copy of the file, its metadata records kept) and must FAIL
REPEATS times out of REPEATS, naming that event. Prints one line per recording
and the totals; exit 1 if any verdict is not the expected one.

    .venv/bin/python tools/verify_soak.py [--out DIR] [--repeats 10] [--sessions 30]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import msgspec
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from pairplay.schemas.events import decode_event, encode_event
from pairplay.services.verify import verify_recording

PERSONAS = ("ashley", "helmut", "tatiana", "vincent", "wasim", "frances", "blind", "deaf")
ROUNDS = (20, 100, 200, 250, 60)  # cycled: every fifth session 250 rounds, 10 of 30 at 200+


def plan(n: int) -> list[tuple[str, int, int, int]]:
    """(persona, seed, game index, rounds) of each session; the issue's cases first."""
    cases = [("blind", 1, 1, 100), ("deaf", 1, 1, 100)]
    i = 0
    while len(cases) < n:
        cases.append((PERSONAS[i % 8], i % 10, i % 5, ROUNDS[i % len(ROUNDS)]))
        i += 1
    return cases[:n]


def pairplay(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pairplay.cli.main", *args], capture_output=True, text=True)


def alter_one_suggestion(src: Path, dst: Path) -> str:
    """Copy `src` with the action of one SuggestionMade (a third of the way in) changed; return its name.
    (mcap's own reader, not the damage-aware one, replay/reader.py: `src` is a recording this soak has just
    verified PASS, whole, with it; mcap's reader raises on any damage it meets, so nothing is lost silently.)"""
    with open(src, "rb") as f:
        reader = make_reader(f)
        messages = list(reader.iter_messages(log_time_order=False))
        # every metadata record too: a copy without them loses what they say (a recovered file's
        # "pairplay.recovered": what its source lost; replay/recover.py)
        metadata = list(reader.iter_metadata())
    made = [i for i, (_, c, m) in enumerate(messages) if c.topic.endswith("/SuggestionMade")]
    target = made[len(made) // 3]
    with open(dst, "wb") as out:
        w = Writer(out, compression=CompressionType.ZSTD)
        w.start(profile="pairplay", library="verify_soak")
        schemas, channels = {}, {}
        for i, (schema, channel, message) in enumerate(messages):
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas[schema.id])
            data = message.data
            if i == target:
                e = decode_event(data)
                e = msgspec.structs.replace(e, action=(e.action + 1) % 88)
                data, name = encode_event(e), f"SuggestionMade seq {e.seq}"
            w.add_message(channels[channel.id], message.log_time, data, message.publish_time, message.sequence)
        for m in metadata:
            w.add_metadata(m.name, dict(m.metadata))
        w.finish()
    return name


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="where the recordings go (default: a temporary folder)")
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--sessions", type=int, default=30)
    ap.add_argument("--cli-every", type=int, default=0, help="every Nth verify by the CLI (0: the first only)")
    ap.add_argument("--reuse", action="store_true", help="keep recordings already in --out (a resumed run)")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="pairplay-soak-"))
    out.mkdir(parents=True, exist_ok=True)
    passed = total = 0
    t0 = time.monotonic()
    recordings = []
    for persona, seed, game, rounds in plan(args.sessions):
        name = f"soak-{persona}-s{seed}-g{game}-r{rounds}"
        path = out / f"{name}.mcap"
        r = None
        if not (args.reuse and path.exists()):
            r = pairplay("session", "--participant", f"sim:{persona}", "--seed", str(seed), "--game-index",
                         str(game), "--rounds", str(rounds), "--session", name, "--out", str(out))
        if not path.exists():
            print(f"{name}: session failed: {r.stderr.strip()[-300:] if r else ''}", flush=True)
            total += args.repeats
            continue
        recordings.append(path)
        ok = 0
        for i in range(args.repeats):
            if i == 0 or (args.cli_every and i % args.cli_every == 0):
                v = pairplay("replay", str(path), "--verify")
                ok += v.returncode == 0 and "verify: PASS" in v.stdout
            else:
                ok += verify_recording(path).ok
        passed += ok
        total += args.repeats
        print(f"{name}: {ok}/{args.repeats} PASS", flush=True)
    failed_named = 0
    if recordings:
        altered = out / "altered.mcap"
        name = alter_one_suggestion(recordings[len(recordings) // 2], altered)
        for _ in range(args.repeats):
            v = pairplay("replay", str(altered), "--verify")
            failed_named += v.returncode == 1 and "verify: FAIL" in v.stdout and f"    {name}:" in v.stdout
        print(f"{altered.name} ({name} altered): {failed_named}/{args.repeats} FAIL naming it", flush=True)
    print(f"verify soak: {passed}/{total} PASS on untouched recordings, {failed_named}/{args.repeats} FAIL on the "
          f"altered one, {time.monotonic() - t0:.0f} s, recordings in {out}")
    return 0 if passed == total and failed_named == args.repeats else 1


if __name__ == "__main__":
    sys.exit(main())

"""Every ordinary mistake, typed as a user would: one line, non-zero exit, nothing written.

Each case runs `python -m pairplay ...` as a process of its own in a folder of its
own (a copy of the same fixtures: a real recording, an empty and a random file,
policy files, existing outputs) and must give: a non-zero exit, exactly one
line on stderr naming the problem, no traceback, and every file of the folder
as it was (nothing replaced, nothing added, no temporary file left). The cases
run in parallel threads, each process forked from one that imported pairplay
once (tests/cli_zygote.py: the import cost 0.2-1.6 s of CPU per case, ~60 s for
the table; what an import prints is checked once, on that process's stderr), so
the table takes seconds. Read-only cases mount a read-only tmpfs (or bind a fixture
folder read-only) in a mount namespace of the command's own, made in the forked child
before the command runs (cli_zygote._read_only: unshare(2), as root); without root
they are skipped.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from pairplay.cli.main import main
from pairplay.replay.mcapscan import scan

from cli_zygote import Zygote
from hints import bad_options

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
CAN_UNSHARE = os.geteuid() == 0  # unshare(2) of a mount namespace (cli_zygote._read_only)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Case:
    name: str
    args: list[str]
    expect: str  # a piece of the one stderr line
    readonly: bool | str = False  # run with ./ro a read-only file system (a name: that folder of the fixtures made read-only)
    code: int = 2
    result: subprocess.CompletedProcess | None = field(default=None, repr=False)
    before: dict = field(default_factory=dict, repr=False)
    after: dict = field(default_factory=dict, repr=False)


TAKEN = socket.socket()  # held open for the whole module: a port in use
TAKEN.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
TAKEN.bind(("127.0.0.1", 0))
TAKEN.listen()
TAKEN_PORT = TAKEN.getsockname()[1]
CLOSED = _closed_port()
SIM = ["session", "--participant", "sim:blind", "--rounds", "2"]

PROC_X = ("cannot write there: its file system makes no new files or folders there (it answered 'No such file or "
          "directory', though /proc exists) (/proc/x)")
PROC = ("cannot write there: its file system makes no new files or folders there (it answered 'No such file or "
        "directory', though the folder exists) (/proc)")
CASES = [
    # a trial: the 'time' rule's settings with another rule were ignored without a word, exit 0 (as LSPI's were)
    Case("session --ignore-window-ms with perceived", SIM + ["--ignore-rule", "perceived", "--ignore-window-ms", "700"],
         "--ignore-window-ms applies to --ignore-rule time only, not perceived"),
    Case("session --ignore-clock for sim's rule", SIM + ["--ignore-clock", "page"],
         "--ignore-clock applies to --ignore-rule time only, not perceived (sim:'s default)"),
    # item 4: input that is not what the verb needs
    Case("recover a missing file", ["recover", "missing.mcap"], "no such recording (missing.mcap)"),
    Case("recover a zero-byte file", ["recover", "empty.mcap"], "the file is empty (0 bytes)"),
    Case("recover random bytes", ["recover", "random.mcap"], "not a recording: not an MCAP file (it does not begin as one) (random.mcap)"),
    # a binary file where a text file is wanted (a traceback before: UnicodeDecodeError, the new-user trial 2026-11-30)
    Case("sweep a binary grid file", ["sweep", "random.mcap"], "random.mcap: not TOML (not UTF-8 text)"),
    # a trial: `--workers 2 --scheduler X` was accepted and --workers ignored (the cluster's workers run the cells)
    Case("sweep --workers with --scheduler", ["sweep", "grid.toml", "--workers", "2", "--scheduler",
                                              f"tcp://127.0.0.1:{_closed_port()}", "--out", "sw"],
         "the cluster's own workers run the cells: give one or the other (--workers 2)"),
    Case("protocol check a binary study file", ["protocol", "check", "random.mcap"],
         "random.mcap: cannot read: not UTF-8 text"),
    Case("recover a folder", ["recover", "policies"], "a folder, not a recording"),
    Case("replay a missing file", ["replay", "missing.mcap"], "no such recording"),
    Case("replay a zero-byte file", ["replay", "empty.mcap", "--speed", "max"], "the file is empty"),
    Case("replay random bytes", ["replay", "random.mcap", "--speed", "max"], "not a recording: not an MCAP file"),
    Case("verify random bytes", ["replay", "random.mcap", "--verify"], "not a recording: not an MCAP file"),
    # a trial: the replay's pace and session id were accepted with --verify, which does not replay on the bus
    Case("verify with --speed", ["replay", "rec.mcap", "--verify", "--speed", "2"],
         "--verify re-runs the recording's services here, off the bus: --speed applies to a replay on the bus only"),
    Case("verify with --as", ["replay", "rec.mcap", "--verify", "--as", "other"], "--as applies to a replay on the bus"),
    Case("view a zero-byte file", ["view", "--recording", "empty.mcap"], "the file is empty"),
    Case("view random bytes", ["view", "--recording", "random.mcap"], "not a recording: not an MCAP file"),
    Case("view a session the recording does not hold",
         ["view", "--recording", "rec.mcap", "--session", "wrong", "--out", "new.rrd"], "holds no events of session wrong"),
    Case("rebuild random bytes", ["rebuild", "random.mcap", "--out", "out"], "not a recording: not an MCAP file"),
    Case("rebuild a missing file", ["rebuild", "rec.mcap", "missing.mcap", "--out", "out"], "no such recording"),
    Case("profile a missing file", ["profile", "missing.json"], "no such policy file"),
    # a recording where a policy file is wanted: "JSON is malformed" before (a researcher's trial)
    Case("profile a recording", ["profile", "rec.mcap"],
         "rec.mcap: an MCAP recording, not a policy file (`pairplay rebuild` makes the policy files of recordings)"),
    Case("pi-reuse from a recording", SIM + ["--algorithm", "pi-reuse", "--policy", "rec.mcap"],
         "an MCAP recording, not a policy file"),
    # item 3: an existing output is never replaced without --force; outputs never collide
    # (of a cut file: a complete one writes nothing, so no output of it is refused)
    Case("recover -o an existing file", ["recover", "cut.mcap", "-o", "existing.mcap"], "exists; --force"),
    Case("recover beside its existing output", ["recover", "old.mcap"], "old.recovered.mcap"),
    Case("view --out an existing .rrd", ["view", "--recording", "rec.mcap", "--out", "existing.rrd"], "exists; --force"),
    Case("view's default .rrd exists", ["view", "--recording", "rec.mcap"], "rec.rrd"),
    Case("combine -o an existing file", ["combine", "policies", "-o", "existing.json"], "exists; --force"),
    Case("combine -o a folder", ["combine", "policies", "-o", "policies"], "is a folder"),
    Case("rebuild over existing outputs", ["rebuild", "rec.mcap", "--out", "rebuilt"], "exists; --force"),
    Case("rebuild the same file twice", ["rebuild", "rec.mcap", "rec.mcap", "--out", "out"], "given twice"),
    Case("rebuild two files of one name", ["rebuild", "rec.mcap", "other/rec.mcap", "--out", "out"],
         "would write the same output"),
    Case("study into a folder with files", ["study", "--quiet", "--out", "policies"], "not empty; --force"),
    # item 5: every option validated, the bus's refusals are one line
    Case("study --out an existing file", ["study", "--quiet", "--out", "existing.json"], "is a file"),
    Case("study --rounds -1", ["study", "--rounds", "-1"], "--rounds: must be at least 1, got -1"),
    Case("study --reuse-seeds 0", ["study", "--reuse-seeds", "0"], "--reuse-seeds: must be at least 1"),
    Case("study --games 0", ["study", "--games", "0"], "--games: must be at least 1"),
    Case("study --psi 2", ["study", "--psi", "2"], "--psi: must be between 0 and 1"),
    Case("study unknown persona", ["study", "--personas", "blind,nobody"], "unknown persona 'nobody'"),
    # an empty item of a comma list is refused, never skipped (pairplay/lists.py: `a,,b` ran a and b without a word)
    Case("study --personas with an empty name", ["study", "--personas", "blind,,deaf"],
         "--personas: 'blind,,deaf' has an empty item (item 2 of 3)"),
    Case("study --personas with a trailing comma", ["study", "--personas", "blind,deaf,"], "(item 3 of 3)"),
    Case("combine --exclude with an empty name", ["combine", "policies", "--exclude", "blind,,deaf"],
         "'blind,,deaf' has an empty item (item 2 of 3): remove the extra comma (--exclude)"),
    Case("robot --try with an empty code", ["robot", "--try", "35,,46"], "'35,,46' has an empty item"),
    Case("bench --only with an empty source", ["bench", "--only", "core,,core"], "has an empty item (item 2 of 3)"),
    Case("counterfactual --policy with an empty arm", ["counterfactual", "rec.mcap", "--policy", "same,,final",
                                                       "--out", "cf"], "'same,,final' has an empty item"),
    Case("protocol pilot --personas with an empty name", ["protocol", "pilot", "study", "--personas", "blind,"],
         "--personas 'blind,' has an empty item (item 2 of 2)"),
    Case("protocol serve --pilot with an empty pair", ["protocol", "serve", "study", "--pilot", ",p01=blind"],
         "--pilot ',p01=blind' has an empty item (item 1 of 2)"),
    # an item named twice where each names one thing done once is refused (pairplay/lists.py `repeated`): `bench
    # --only core,core` measured core twice and printed both sets of rows (trial34 G)
    Case("bench --only a source twice", ["bench", "--only", "core,core", "--quick"],
         "'core,core' names core twice: each source is measured once (--only)"),
    Case("run game --wait-for a service twice", ["run", "game", "--wait-for", "learner,learner"],
         "'learner,learner' names learner twice: each service is waited for once"),
    Case("counterfactual --policy an arm twice", ["counterfactual", "rec.mcap", "--policy", "same,final,same",
                                                  "--out", "cf"], "the arm same is given twice: each arm is measured once"),
    Case("study --personas a persona twice", ["study", "--personas", "blind,blind"],
         "--personas: names blind twice: each persona is trained once"),
    # a comma list that names nothing is refused too: `bench --only ""` measured nothing and exited 0 with an
    # empty table, `counterfactual --policy ""` quietly only fitted (a shell variable left empty)
    Case("bench --only empty", ["bench", "--only", ""], "'' names nothing: give one or more, comma-separated (--only)"),
    Case("bench --only blank", ["bench", "--only", " "], "' ' names nothing"),
    Case("counterfactual --policy empty", ["counterfactual", "rec.mcap", "--policy", "", "--out", "cf"],
         "'' names nothing: give one or more, comma-separated (--policy)"),
    Case("combine --exclude empty", ["combine", "policies", "--exclude", " "], "' ' names nothing"),
    Case("robot --try empty", ["robot", "--try", ""], "'' names nothing"),
    Case("run --wait-for empty", ["run", "game", "--wait-for", ""], "'' names nothing"),
    Case("study --personas empty", ["study", "--personas", ""], "--personas: names no persona"),
    Case("protocol pilot --personas empty", ["protocol", "pilot", "study", "--personas", ""],
         "--personas '' names nothing"),
    Case("protocol serve --pilot empty", ["protocol", "serve", "study", "--pilot", ""], "--pilot '' names nothing"),
    # a new user's trial: a misspelt option was argparse's "unrecognized arguments: --forse", with no hint (every
    # other misspelt name had one: pairplay/nearest.py); said in pairplay's words, with the option it resembles
    Case("study --forse", ["study", "--forse"], "unknown option --forse (did you mean --force?)"),
    Case("combine --forse with a value", ["combine", "policies", "--forse", "1"],
         "unknown option --forse (did you mean --force?) (see"),
    Case("protocol init --key-fiel=FILE", ["protocol", "init", "st", "--study", "thesis-ch7", "--key-fiel=k.csv"],
         "unknown option --key-fiel=k.csv (did you mean --key-file?)"),
    # ...and before what is missing, which it may be misspelt: "the following arguments are required: --study"
    Case("protocol init --studdy", ["protocol", "init", "st", "--studdy", "thesis-ch7"],
         "unknown option --studdy (did you mean --study?)"),
    # a misspelt persona is said before the count of them (one of two names counted for one participant, p01:
    # it said "--personas names 2 personas for 1 registered participant", and only then the misspelling)
    Case("protocol pilot --personas misspelt and too many", ["protocol", "pilot", "study", "--personas", "ashly,blind"],
         "unknown persona 'ashly' (did you mean 'ashley'?)"),
    Case("session --game-index -1", SIM + ["--game-index", "-1"], "--game-index: must be at least 0"),
    Case("session --rounds 0", SIM[:3] + ["--rounds", "0"], "--rounds: must be at least 1"),
    Case("session --policy with q-learning", SIM + ["--policy", "existing.json"], "--policy is used only by"),
    Case("session pi-reuse without --policy", SIM + ["--algorithm", "pi-reuse"], "needs --policy"),
    # its one round under human-phase2 is the last, on the new policy alone: it never reused (Q-learning)
    Case("session pi-reuse of 1 round", ["session", "--participant", "human:p9", "--algorithm", "pi-reuse",
                                         "--policy", "policies/blind/game-00.json", "--rounds", "1"],
         "--algorithm pi-reuse with --rounds 1 would never reuse the bias policy"),
    Case("session --policy not a policy", SIM + ["--algorithm", "pi-reuse", "--policy", "random.mcap"], "random.mcap"),
    Case("session unknown persona", ["session", "--participant", "sim:nobody"], "unknown persona"),
    Case("session --out an existing file", SIM + ["--out", "existing.json"], "is a file, not a folder"),
    Case("session bad --listen", SIM + ["--listen", "bogus"], "bad bus endpoint"),
    Case("session --listen a port in use", SIM + ["--listen", f"tcp/127.0.0.1:{TAKEN_PORT}"],
         f"--listen tcp/127.0.0.1:{TAKEN_PORT}"),
    Case("session unreachable --connect", SIM + ["--connect", f"tcp/127.0.0.1:{CLOSED}"], "cannot open the bus"),
    Case("session missing --zenoh-config", SIM + ["--zenoh-config", "missing.json5"], "--zenoh-config missing.json5"),
    Case("session invalid --zenoh-config", SIM + ["--zenoh-config", "random.mcap"], "cannot use the Zenoh config"),
    Case("run a learner without --session", ["run", "learner"], "--session is required"),
    # a service that joins a session follows its config: a session's option it is given is refused, not ignored
    Case("run learner --algorithm", ["run", "learner", "--session", "s", "--algorithm", "lspi"],
         "--algorithm lspi is not taken by pairplay run learner"),
    Case("run learner --policy", ["run", "learner", "--session", "s", "--policy", "existing.json"],
         "--policy existing.json is not taken by pairplay run learner"),
    Case("run participant --rounds", ["run", "participant", "--session", "s", "--rounds", "3"],
         "--rounds 3 is not taken by pairplay run participant"),
    Case("run game restarted with --seed", ["run", "game", "--session", "s", "--seed", "3"],
         "a game restarted by --session alone plays the config in the session's log"),
    Case("run recorder --wait-for", ["run", "recorder", "--session", "s", "--wait-for", "learner"],
         "--wait-for learner is not taken by pairplay run recorder: used by the game only"),
    Case("run learner --participant", ["run", "learner", "--session", "s", "--participant", "sim:ashley"],
         "--participant sim:ashley is not taken by pairplay run learner"),
    Case("run game --out", ["run", "game", "--participant", "sim:ashley", "--out", "d"],
         "--out d is not taken by pairplay run game"),
    Case("run learner --settle", ["run", "learner", "--session", "s", "--settle", "5"],
         "--settle 5 is not taken by pairplay run learner: used by the game only"),
    Case("run game --settle without a recorder to wait for", ["run", "game", "--participant", "sim:ashley",
                                                              "--settle", "5"],
         "--settle 5 is the time a recorder the game waits for may be off the bus: give --wait-for recorder too"),
    Case("replay --as 'bad id'", ["replay", "rec.mcap", "--as", "bad id"], "--as: session id 'bad id'"),
    Case("replay --speed -1", ["replay", "rec.mcap", "--speed", "-1"], "--speed: must be max (or 0"),
    Case("view --speed -1", ["view", "--recording", "rec.mcap", "--speed", "-1", "--out", "new.rrd"],
         "--speed: must be max (or 0"),
    Case("view --serve with its data port taken",
         ["view", "--recording", "rec.mcap", "--serve", "--no-save", "--grpc-port", str(TAKEN_PORT), "--web-port", "0"],
         f"--grpc-port {TAKEN_PORT}"),
    Case("view without a source", ["view"], "give --session ID"),
    Case("view live with an unreachable --connect", ["view", "--session", "s1", "--connect", f"tcp/127.0.0.1:{CLOSED}"],
         "cannot open the bus"),
    Case("replay to an unreachable --connect", ["replay", "rec.mcap", "--connect", f"tcp/127.0.0.1:{CLOSED}"],
         "cannot open the bus"),
    Case("study --eval-rounds 0", ["study", "--eval-rounds", "0"], "--eval-rounds: must be at least 1"),
    # numbers that size memory or feed the learner are bounded before any work (a new user's trial,
    # 2026-12-01): each of these was a MemoryError traceback or an OOM kill, a hang, or learned nonsense
    # a session over the bus holds ~0.35 MB a round until it ends (cli/args.py SESSION_ROUNDS_MAX):
    # `--rounds 1000000000` was taken and grew to 3.7 GB in 10 minutes before it was killed
    *(Case(f"{verb} --rounds 1000000000", [*verb, "--participant", who, "--rounds", "1000000000"],
           "--rounds: must be 1..5000 (a session over the bus holds ~0.35 MB a round until it ends: at most ~2 GB), "
           "got 1000000000") for verb, who in ((["session"], "sim:ashley"), (["lab"], "human:p1"),
                                                (["run", "game"], "sim:ashley"))),
    Case("session --rounds 5001", ["session", "--participant", "sim:ashley", "--rounds", "5001"],
         "--rounds: must be 1..5000"),
    Case("study --games 1000000000", ["study", "--games", "1000000000"],
         "--games: the study would hold about 3795200.3 GB of memory (8 personas, --games 1000000000"),
    Case("study --rounds 1000000000", ["study", "--rounds", "1000000000"], "--rounds: the study would hold about"),
    Case("study --eval-rounds 1000000000", ["study", "--eval-rounds", "1000000000"],
         "--eval-rounds: the study would hold about"),
    Case("study of one persona --rounds 100000000", ["study", "--personas", "blind", "--rounds", "100000000"],
         "--rounds: the study would hold about 50.0 GB of memory (1 persona, --games 10, --rounds 100000000, "
         "--eval-rounds 200), over the 2.0 GB allowed"),
    Case("counterfactual --rounds 100000000", ["counterfactual", "rec.mcap", "--rounds", "100000000", "--out", "cf"],
         "3 arms x 10 seeds x 100000000 rounds would hold about 6010.0 GB of memory (every turn is kept for "
         "counterfactual.csv), over the 2.0 GB allowed: give fewer rounds, seeds or arms (--rounds 100000000)"),
    Case("counterfactual --seeds 100000000", ["counterfactual", "rec.mcap", "--seeds", "100000000", "--out", "cf"],
         "(--seeds 100000000)"),
    Case("sweep a grid of 10**10 rounds", ["sweep", "huge-rounds.toml", "--out", "sw"],
         "huge-rounds.toml: [study] rounds = 10000000000: the study would hold about"),
    Case("sweep a grid of 10**8 seeds", ["sweep", "huge-seeds.toml", "--out", "sw"],
         "huge-seeds.toml: seeds = 100000000: 1 setting x 100000000 seeds is over the 10000 cells a sweep may have"),
    Case("protocol check a learner override of nan", ["protocol", "check", "alpha-nan.toml"],
         'alpha-nan.toml: [[phase]] "phase1" learner.alpha_start: must be 0..1, got nan'),
    Case("protocol check an epsilon of 5", ["protocol", "check", "epsilon-5.toml"],
         'epsilon-5.toml: [[phase]] "phase1" learner.epsilon_start: must be 0..1, got 5.0'),
    Case("protocol check an ignore window of inf", ["protocol", "check", "window-inf.toml"],
         "window-inf.toml: [study] ignore_window_ms: must be 0..60000 (ms), got inf"),
    Case("protocol check a turn-back time of nan", ["protocol", "check", "turn-nan.toml"],
         "turn-nan.toml: [study] turn_back_ms: must be 0..60000 (ms), got nan"),
    Case("replay --speed nan", ["replay", "rec.mcap", "--speed", "nan"], "--speed: must be max (or 0"),
    Case("view --speed 1e-300", ["view", "--recording", "rec.mcap", "--speed", "1e-300", "--out", "new.rrd"],
         "--speed: must be max (or 0, as fast as possible) or 0.0001..1e+06 times real time"),
    Case("combine a policy of -3 rounds", ["combine", "policies", "bad/rounds-neg.json", "-o", "m.json"],
         "bad/rounds-neg.json: corrupt or not a policy file: rounds: must be 0..9007199254740992, got -3"),
    Case("profile a policy of negative visits", ["profile", "policies/blind", "bad/visits-neg.json"],
         "bad/visits-neg.json: corrupt or not a policy file: visits[0]: must be 0..9007199254740992 (updates of the "
         "state), got -100"),
    # beyond int64: a traceback (OverflowError in core/policies.py check_distinct) in both verbs (trial28 F6)
    Case("profile a policy of visits 10**30", ["profile", "policies/blind", "bad/visits-huge.json"],
         "bad/visits-huge.json: corrupt or not a policy file: visits[1]: must be 0..9007199254740992 (updates of "
         "the state), got a number of 31 digits"),
    Case("combine a policy of visits 10**30", ["combine", "policies", "bad/visits-huge.json", "-o", "m.json"],
         "bad/visits-huge.json: corrupt or not a policy file: visits[1]: must be 0..9007199254740992"),
    # rows are read by position: the reversed names were read silently as pairplay's order (trial28 F7)
    Case("profile a policy whose states are in another order", ["profile", "policies/blind", "bad/states-reversed.json"],
         "bad/states-reversed.json: corrupt or not a policy file: states[0]: must be 'TOP_LEFT_L0' (a policy names "
         "the 24 states in pairplay's order, one row each), got 'NOT_ONE_CARD'"),
    Case("combine a policy of a seed beyond 64 bits", ["combine", "policies", "bad/seed-huge.json", "-o", "m.json"],
         "bad/seed-huge.json: corrupt or not a policy file: seed: must be 0..18446744073709551615, got 18446744073709551616"),
    Case("combine a policy of no participant", ["combine", "policies", "bad/participant-empty.json", "-o", "m.json"],
         "bad/participant-empty.json: corrupt or not a policy file: participant: empty"),
    Case("session --policy with a Q of 1e308", SIM + ["--algorithm", "pi-reuse", "--policy", "bad/q-huge.json"],
         "bad/q-huge.json: corrupt or not a policy file: q: must be -1e+06..1e+06 (a reward's size), got 1e+308"),
    # JSON files in the file's words, not msgspec's ("Expected `float`, got `str` - at `$.q[0][1]`",
    # "Object contains unknown field `yaw_sgn`"): schemas/jsonfile.py in_words
    Case("combine a policy with text in its Q-table", ["combine", "policies", "bad/q-text.json", "-o", "m.json"],
         "bad/q-text.json: corrupt or not a policy file: q[0][1]: must be a number, got text"),
    Case("robot --try with a misspelt robot config key", ["robot", "--try", "3", "--robot-config", "rc-typo.json"],
         "robot config rc-typo.json is not valid: no key `yaw_sgn` is known here (did you mean `yaw_sign`?)"),
    Case("robot --try with a calibration of text", ["robot", "--try", "3", "--calibration", "cal-text.json"],
         "calibration cal-text.json is not valid: cards[0][2]: must be a number, got text"),
    Case("session with a bad session id", SIM + ["--session", "a/b"], "session id 'a/b'"),
    Case("combine nothing left after --exclude", ["combine", "policies", "--exclude", "blind,deaf"],
         "no policies left to combine"),
    Case("profile --min-updates -1", ["profile", "policies", "--min-updates", "-1"], "must be at least 0"),
    Case("robot --try against a refused connection", ["robot", "--try", "35", "--robot", f"iristk://127.0.0.1:{CLOSED}"],
         "does not accept a connection"),
    Case("robot --try a code out of range", ["robot", "--try", "88"], "action codes are integers 0..87"),
    # a session with a robot it cannot reach ran to exit 0, every suggestion failed, said only under -v
    Case("session with an unreachable robot", SIM + ["--robot", f"furhat://127.0.0.1:{CLOSED}?key=secret"],
         "does not accept a connection: Connection refused; --robot-unreachable-ok starts the session anyway"),
    Case("lab with an unreachable robot", ["lab", "--participant", "human:p1", "--robot",
                                           f"iristk://127.0.0.1:{CLOSED}"], "--robot-unreachable-ok"),
    # item 7: meaningless input to combine and profile
    Case("combine the same file twice", ["combine", "policies/blind/game-00.json", "policies/blind/game-00.json",
                                         "policies/deaf"], "given twice"),
    Case("combine a folder twice", ["combine", "policies", "policies"], "given twice"),
    Case("combine a copy of a policy", ["combine", "policies", "copy.json"], "the same policy as"),
    Case("profile a single policy", ["profile", "policies/blind/game-00.json"], "compares two or more policies"),
    Case("combine --exclude a typo", ["combine", "policies", "--exclude", "blnd"],
         "no policy of 'blnd' (did you mean 'blind'?)"),
    # a misspelt name of every comma list is said with the one it resembles, as a persona's is (pairplay/nearest.py
    # `hinted`): before, no hint (and bench printed a Python list, `unknown source(s) ['cor']`)
    Case("bench --only a typo", ["bench", "--only", "cor,bus"],
         "unknown source 'cor' (did you mean 'core'?); known: core, lspi, bus, view, robot, lab (--only)"),
    Case("run --wait-for a typo", ["run", "game", "--participant", "sim:blind", "--wait-for", "learnr,recorder"],
         "'learnr' (did you mean 'learner'?): not a service to wait for"),
    # options only the arms take, with --fit-only that plays none: ignored, exit 0 (a new user's trial)
    Case("counterfactual --fit-only --policy", ["counterfactual", "rec.mcap", "--fit-only", "--policy", "same",
                                                 "--out", "cf"],
         "--policy same is not taken with --fit-only: it plays no arm"),
    Case("counterfactual --fit-only --seeds", ["counterfactual", "rec.mcap", "--seeds", "3", "--fit-only",
                                                "--out", "cf"], "--seeds 3 is not taken with --fit-only"),
    Case("counterfactual --fit-only --seed", ["counterfactual", "rec.mcap", "--fit-only", "--seed", "0",
                                               "--out", "cf"], "--seed 0 is not taken with --fit-only"),
    Case("counterfactual --fit-only --rounds", ["counterfactual", "rec.mcap", "--fit-only", "--rounds", "5",
                                                 "--out", "cf"], "--rounds 5 is not taken with --fit-only"),
    # the unreadable file's arm and option named ("nope.json: cannot read" named neither)
    Case("counterfactual --policy reuse of a missing file", ["counterfactual", "rec.mcap", "--policy",
                                                               "same,reuse:nope.json", "--out", "cf12"],
         "counterfactual: --policy reuse:nope.json: cannot read: No such file or directory"),
    Case("counterfactual --policy fixed of a folder", ["counterfactual", "rec.mcap", "--policy", "fixed:policies",
                                                        "--out", "cf12"], "--policy fixed:policies: "),
    # a policy file an option names: the refusal names the option ("nope.json: cannot read" named none)
    Case("session --policy a missing file", SIM + ["--algorithm", "pi-reuse", "--policy", "nope.json"],
         "session: --policy nope.json: cannot read: No such file or directory"),
    Case("report --reference a missing file", ["report", "study", "--reference", "nope.json"],
         "report: --reference nope.json: cannot read: No such file or directory"),
    # one policy of a participant has no profile (algorithm 3): merged as perceiving everything, exit 0 (a trial)
    Case("combine one policy", ["combine", "policies/blind/game-00.json", "-o", "m1.json"],
         "a merge (algorithm 4) weighs each participant by its profile (algorithm 3), which compares two or more "
         "policies of a participant; only one of blind (policies/blind/game-00.json)"),
    Case("combine one policy of one of two participants", ["combine", "policies/deaf", "policies/blind/game-01.json"],
         "only one of blind (policies/blind/game-01.json)"),
    Case("counterfactual --policy a typo", ["counterfactual", "rec.mcap", "--policy", "same,fnal", "--out", "cf"],
         "unknown arm 'fnal' (did you mean 'final'?)"),
    Case("counterfactual --policy reuse without its file", ["counterfactual", "rec.mcap", "--policy", "reuse",
                                                            "--out", "cf"], "unknown arm 'reuse' (did you mean 'reuse:FILE'?)"),
    Case("combine mixed reward rules names the files", ["combine", "policies/deaf", "spec/blind.json"],
         "consistent: spec/blind.json"),
    # profile pooled a participant's policies of different reward rules without a word (a new user's trial,
    # `profile q1/policies q2/policies --actions`), where combine refused the same files
    Case("profile mixed reward rules names the files", ["profile", "policies/blind/game-01.json", "spec/blind.json",
                                                        "policies/deaf", "--actions"],
         "their Q-values cannot be compared; consistent: spec/blind.json; correct: policies/blind/game-01.json"),
    # found by the trial (2026-11-30): the lab's pages on a port in use printed uvicorn's own ERROR line
    # beside ours (two lines; the lab exited 1)
    Case("lab --listen a port in use", ["lab", "--participant", "human:p1", "--listen", f"127.0.0.1:{TAKEN_PORT}"],
         f"Address already in use (--listen 127.0.0.1:{TAKEN_PORT})"),
    Case("protocol serve --listen a port in use", ["protocol", "serve", "study", "--listen", f"127.0.0.1:{TAKEN_PORT}"],
         f"cannot serve the console: Address already in use (--listen 127.0.0.1:{TAKEN_PORT})"),  # the lab's words
    # trial36 P1: serve took 99999 as port 34463 (99999 mod 65536) where the lab refuses it
    Case("protocol serve --listen a port past 65535", ["protocol", "serve", "study", "--listen", "127.0.0.1:99999"],
         "--listen '127.0.0.1:99999': use HOST:PORT, e.g. 127.0.0.1:8080 (port 0: a free one)"),
    # read-only places (a read-only tmpfs mounted at ./ro)
    Case("study --out on a read-only file system", ["study", "--quiet", "--out", "ro/study"], "read-only", readonly=True),
    Case("session --out on a read-only file system", SIM + ["--out", "ro/rec"], "read-only", readonly=True),
    Case("combine -o on a read-only file system", ["combine", "policies", "-o", "ro/m.json"], "read-only", readonly=True),
    Case("recover -o on a read-only file system", ["recover", "cut.mcap", "-o", "ro/r.mcap"], "read-only", readonly=True),
    Case("rebuild --out on a read-only file system", ["rebuild", "rec.mcap", "--out", "ro"], "read-only", readonly=True),
    # every other verb's outputs, and a file option given as the read-only folder (`-o ro/`: the file goes in it)
    Case("recover -o into a read-only folder", ["recover", "cut.mcap", "-o", "ro/"], "read-only (ro)", readonly=True),
    Case("view --out on a read-only file system", ["view", "--recording", "rec.mcap", "--out", "ro/v.rrd"],
         "read-only (ro)", readonly=True),
    Case("view --out into a read-only folder", ["view", "--recording", "rec.mcap", "--out", "ro/"], "read-only (ro)",
         readonly=True),
    Case("counterfactual --out on a read-only file system", ["counterfactual", "rec.mcap", "--out", "ro/cf"],
         "read-only (ro)", readonly=True),
    Case("sweep --out on a read-only file system", ["sweep", "grid.toml", "--out", "ro/sw"], "read-only (ro)",
         readonly=True),
    Case("report --out on a read-only file system", ["report", "study", "--out", "ro/rep"], "read-only (ro)",
         readonly=True),
    Case("run recorder --out on a read-only file system", ["run", "recorder", "--session", "s", "--out", "ro/x"],
         "read-only (ro)", readonly=True),
    Case("lab --out on a read-only file system", ["lab", "--participant", "human:p1", "--out", "ro/x"],
         "read-only (ro)", readonly=True),
    Case("protocol init on a read-only file system", ["protocol", "init", "ro/st", "--study", "thesis-ch7"],
         "read-only (ro)", readonly=True),
    # before: the key file's line named the resolved path (/tmp/.../ro/keys.csv), not the one typed
    Case("protocol init --key-file on a read-only file system", ["protocol", "init", "st", "--study", "thesis-ch7",
                                                                 "--key-file", "ro/keys.csv"],
         "cannot write the key file there: Read-only file system (ro/keys.csv)", readonly=True),
    # "what (where)" as every other refusal (pairplay/outputs.py check_output's words): before, `<path> exists
    # (use --force to replace it)`, `<folder>: already a study folder`, `key file <path>: <why>`
    Case("participant export -o over an existing file", ["participant", "export", "study", "p01", "-o", "rec.mcap"],
         "exists; --force replaces it (rec.mcap)"),
    Case("protocol init an existing study folder", ["protocol", "init", "study", "--study", "thesis-ch7"],
         "already initialised (journal.jsonl is there); give another folder (study)"),
    Case("participant export -o on a read-only file system", ["participant", "export", "study", "p01", "-o",
                                                              "ro/p.zip"], "read-only (ro)", readonly=True),
    # a study folder one may not write in: before, `protocol serve` served its console (each step then failed),
    # and the others named the resolved path of the file they failed on (/tmp/.../study/journal.jsonl)
    Case("participant export into a read-only study", ["participant", "export", "study", "p01"],
         "read-only (study)", readonly="study"),
    Case("participant delete in a read-only study", ["participant", "delete", "study", "p01", "--yes"],
         "read-only (study)", readonly="study"),
    # the console refused these and the command line took them (trial15): one rule, in replay/studydata.py
    Case("protocol mark-invalid with an empty reason", ["protocol", "mark-invalid", "study", "s1", "--reason", ""],
         "marking a session invalid needs a reason"),
    Case("protocol mark-invalid with a blank reason", ["protocol", "mark-invalid", "study", "s1", "--reason", "  "],
         "marking a session invalid needs a reason"),
    Case("protocol register in a read-only study", ["protocol", "register", "study"], "read-only (study)",
         readonly="study"),
    Case("protocol mark-invalid in a read-only study", ["protocol", "mark-invalid", "study", "s1", "--reason", "x"],
         "read-only (study)", readonly="study"),
    Case("protocol pilot in a read-only study", ["protocol", "pilot", "study", "--personas", "blind"],
         "read-only (study)", readonly="study"),
    Case("protocol serve a read-only study", ["protocol", "serve", "study"], "read-only (study)", readonly="study"),
    # a file holding no session (a new user's trial, 2026-11-30): recover wrote an empty file and exit 0,
    # verify said it on stdout with exit 1, rebuild of such files exit 1, view printed 3 lines
    # said in a user's words (not "only MCAP's magic")
    Case("recover MCAP's magic alone", ["recover", "magic.mcap"],
         "holds no session: an MCAP file with no records (8 bytes): the recording holds nothing"),
    Case("recover 10 bytes", ["recover", "ten.mcap"],
         "holds no session: an MCAP file with no records (10 bytes): the recording holds nothing"),
    Case("recover a header alone", ["recover", "header.mcap"], "holds no session: an MCAP file with no messages ("),
    Case("recover another program's MCAP", ["recover", "foreign.mcap"], "not a pairplay recording"),
    Case("recover a session never started", ["recover", "nostart.mcap"], "no SessionStarted (a session that never"),
    Case("verify a session never started", ["replay", "nostart.mcap", "--verify"], "holds no session"),
    Case("verify MCAP's magic alone", ["replay", "magic.mcap", "--verify"], "holds no session"),
    Case("replay another program's MCAP", ["replay", "foreign.mcap", "--speed", "max"], "not a pairplay recording"),
    Case("rebuild a file holding no session beside a good one", ["rebuild", "rec.mcap", "nostart.mcap", "--out", "out"],
         "holds no session"),
    Case("rebuild only files holding no session", ["rebuild", "magic.mcap", "header.mcap", "--out", "out"],
         "holds no session"),
    Case("view a header alone", ["view", "--recording", "header.mcap", "--out", "new.rrd"], "holds no session"),
    Case("counterfactual of 10 bytes", ["counterfactual", "ten.mcap", "--out", "cf"], "holds no session"),
    # a session with no round recorded whole (a new user's trial, 2026-12-01): verify said "PASS as far as the
    # file goes" and rebuild wrote a policy of 0 rounds, both exit 0
    Case("verify a file cut before its first round", ["replay", "cut.mcap", "--verify"],
         "holds no whole round: the file is cut before round 1 of "),
    Case("rebuild a file cut before its first round", ["rebuild", "cut.mcap", "--out", "out"],
         "holds no whole round: the file is cut before round 1 of "),
    Case("rebuild a session stopped in round 1 beside a good one", ["rebuild", "rec.mcap", "stopped0.mcap", "--out",
                                                                    "out"], "nothing to rebuild; leave it out, or --partial rebuilds the others without it (stopped0.mcap)"),
    Case("combine a policy of 0 rounds", ["combine", "policies", "zero.json"], "holds no whole round"),
    Case("profile a policy of 0 rounds", ["profile", "policies", "zero.json"], "holds no whole round"),
    # an empty or blank id was taken (`--session ''` fell back to a made-up id); a refused atomic write
    # named the temporary file beside the user's
    Case("session --session ''", SIM + ["--session", ""], "session id '' must be non-empty"),
    Case("session --session blank", SIM + ["--session", " \t"], "session id ' \\t' must be non-empty"),
    Case("run learner --session ''", ["run", "learner", "--session", ""], "session id '' must be non-empty"),
    # before (a new user's trial): accepted, and the recorder wrote -x.mcap, a file commands take for an option
    Case("run recorder --session=-x", ["run", "recorder", "--session=-x"], "session id '-x' must not start with '-'"),
    Case("replay --as blank", ["replay", "rec.mcap", "--as", " "], "session id ' ' must be non-empty"),
    Case("participant export an empty id", ["participant", "export", "study", ""], "participant id '' must be"),
    Case("study --out where no folder can be made", ["study", "--quiet", "--train-only", "--out", "/proc/forbidden"],
         "(/proc/forbidden)"),
    # an output the system refuses although os.access says yes (root in /proc): refused before the bus
    # opens and before any line (session printed "bus listening ..." first; lab served its pages and blamed
    # --listen; run recorder printed "listening")
    Case("session --out where no folder can be made", SIM + ["--out", "/proc/x"],
         PROC_X),
    Case("lab --out where no folder can be made", ["lab", "--participant", "human:p1", "--out", "/proc/x"],
         PROC_X),
    Case("run recorder --out where no folder can be made", ["run", "recorder", "--session", "s", "--out", "/proc/x"],
         PROC_X),
    Case("rebuild --out where no folder can be made", ["rebuild", "rec.mcap", "--out", "/proc/x"], "(/proc/x)"),
    Case("recover -o where no file can be made", ["recover", "cut.mcap", "-o", "/proc/x.mcap"], "(/proc)"),
    # /proc's "No such file or directory" was said as the reason, of a folder that exists (a new user's trial)
    Case("combine -o where no file can be made", ["combine", "policies", "-o", "/proc/m.json"],
         "cannot write there: its file system makes no new files or folders there (it answered 'No such file or "
         "directory', though the folder exists) (/proc)"),
    Case("counterfactual --out where no folder can be made", ["counterfactual", "rec.mcap", "--out", "/proc/x"],
         "(/proc/x)"),
    Case("sweep --out where no folder can be made", ["sweep", "grid.toml", "--out", "/proc/x"], "(/proc/x)"),
    Case("participant export -o where no file can be made", ["participant", "export", "study", "p01", "-o",
                                                             "/proc/p.zip"], PROC),
    Case("protocol init where no folder can be made", ["protocol", "init", "/proc/st", "--study", "thesis-ch7"],
         PROC_X.replace("/proc/x", "/proc/st")),
]


def _snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(root.rglob("*"))}


def _fixtures(root: Path) -> None:
    shutil.copy(SAMPLE, root / "rec.mcap")
    last = scan(SAMPLE).chunks[-1]  # cut after its last chunk, as a crash leaves it: recover has work to do
    (root / "old.mcap").write_bytes(SAMPLE.read_bytes()[:last.offset + last.length])
    (root / "other").mkdir()
    shutil.copy(SAMPLE, root / "other" / "rec.mcap")
    (root / "old.recovered.mcap").write_bytes(b"the user's file")
    (root / "empty.mcap").write_bytes(b"")
    (root / "random.mcap").write_bytes(os.urandom(2000))
    _no_session_files(root)
    for name in ("existing.mcap", "existing.rrd", "existing.json", "rec.rrd"):
        (root / name).write_bytes(b"the user's file " + name.encode())
    assert main(["study", "--quiet", "--train-only", "--personas", "blind,deaf", "--games", "2", "--rounds", "20",
                 "--out", str(root / "study")]) == 0
    shutil.move(root / "study" / "policies", root / "policies")
    shutil.rmtree(root / "study")
    shutil.copy(root / "policies" / "blind" / "game-01.json", root / "copy.json")
    spec = json.loads((root / "policies" / "blind" / "game-00.json").read_text())
    spec["reward_bonus"] = "consistent"
    (root / "spec").mkdir()
    (root / "spec" / "blind.json").write_text(json.dumps(spec))
    _no_round_files(root)
    (root / "rebuilt").mkdir()
    (root / "rebuilt" / "rec.policy.json").write_bytes(b"the user's rebuilt policy")
    (root / "ro").mkdir()
    (root / "grid.toml").write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 20\n'
                                    '[grid]\ntrained_updates = [50]\n')
    (root / "huge-rounds.toml").write_text('seeds = 2\n[study]\nrounds = 10000000000\n[grid]\ntrained_updates = [50]\n')
    (root / "huge-seeds.toml").write_text('seeds = 100000000\n[grid]\ntrained_updates = [50]\n')
    from pairplay.schemas.study import example_text
    example = example_text()
    phase1 = 'preset = "human-phase1"\n'
    assert phase1 in example and "ignore_window_ms = 1500\n" in example
    for name, text in (("alpha-nan", example.replace(phase1, phase1 + "learner = { alpha_start = nan }\n", 1)),
                       ("epsilon-5", example.replace(phase1, phase1 + "learner = { epsilon_start = 5.0, alpha_start = -3.0 }\n", 1)),
                       ("window-inf", example.replace("ignore_window_ms = 1500\n", "ignore_window_ms = inf\n")),
                       ("turn-nan", example.replace("ignore_window_ms = 1500\n", "turn_back_ms = nan\n"))):
        (root / f"{name}.toml").write_text(text)
    good = json.loads((root / "policies" / "blind" / "game-00.json").read_text())
    (root / "bad").mkdir()
    q_huge = [row[:] for row in good["q"]]
    q_huge[0][0] = 1e308
    visits_more = [good["visits"][0] + 1] + good["visits"][1:]
    for name, change in (("rounds-neg", {"rounds": -3}), ("visits-neg", {"visits": [-100] + good["visits"][1:]}),
                         ("participant-empty", {"participant": ""}), ("q-huge", {"q": q_huge}),
                         ("visits-huge", {"visits": good["visits"][:1] + [10**30] + good["visits"][2:]}),
                         # (one visit more: not the same learning as game-00, which is refused as given twice)
                         ("states-reversed", {"states": good["states"][::-1], "visits": visits_more}),
                         ("seed-huge", {"seed": 2**64, "visits": visits_more})):
        (root / "bad" / f"{name}.json").write_text(json.dumps({**good, **change}))
    q_text = [row[:] for row in good["q"]]
    q_text[0][1] = "x"
    (root / "bad" / "q-text.json").write_text(json.dumps({**good, "q": q_text}))
    (root / "rc-typo.json").write_text('{"yaw_sgn": -1}')
    (root / "cal-text.json").write_text('{"cards": [[0.1, 0.2, "near"]]}')
    assert main(["protocol", "init", str(root / "study"), "--study", "thesis-ch7", "--quiet"]) == 0
    assert main(["protocol", "register", str(root / "study"), "--count", "1", "--quiet"]) == 0  # p01


ENV = dict(os.environ, COLUMNS="200")


def _no_session_files(root: Path) -> None:
    """MCAP files holding no session: the magic alone, 10 bytes, a header alone, another program's
    MCAP, a pairplay recording of a session that never started (one ServiceStarted)."""
    from mcap.writer import Writer

    from pairplay.replay.writer import EventLogWriter
    from pairplay.schemas.envelope import stamped
    from pairplay.schemas.events import ServiceStarted, encode_event
    from pairplay.schemas.keys import event_key

    magic = b"\x89MCAP0\r\n"
    (root / "magic.mcap").write_bytes(magic)
    (root / "ten.mcap").write_bytes(magic + b"\x01\x02")
    with open(root / "header.mcap", "wb") as f:
        Writer(f).start(profile="", library="a recorder that died at once")
    with open(root / "foreign.mcap", "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="another program")
        w.add_message(w.register_channel("/chatter", "json", w.register_schema("s", "jsonschema", b"{}")), 1, b"{}", 1)
        w.finish()
    w = EventLogWriter(root / "nostart.mcap")
    e = stamped(ServiceStarted(service="learner", version="x"), session="s1", source="learner", seq=1, time_ns=10)
    w.write(event_key("s1", "learner", "ServiceStarted"), encode_event(e), log_time_ns=10)
    w.close()



def _no_round_files(root: Path) -> None:
    """Recordings whose session has no round recorded whole (a new user's trial, 2026-12-01: verify
    said "PASS as far as the file goes", rebuild wrote a policy of 0 rounds, both exit 0): cut.mcap,
    the sample's events up to its first RoundEnded in a file cut after its last chunk (summary and
    footer lost, as a crash leaves it); stopped0.mcap, its events up to the game's second
    turn, then the game's SessionEnded as its shell writes it (interrupted in round 1 after 2 turns), a
    whole file (verified: its whole life is in it; not rebuilt: a policy of 0 rounds); and zero.json, a learned policy of 0 rounds, no state updated."""

    from pairplay.replay.mcapscan import scan
    from pairplay.replay.reader import read_log
    from pairplay.replay.writer import EventLogWriter
    from pairplay.schemas.envelope import stamped
    from pairplay.schemas.events import SessionEnded, encode_event
    from pairplay.schemas.keys import event_key

    events = []
    for r in read_log(SAMPLE).events:
        if type(r.event).__name__ == "RoundEnded" and r.event.source == "game":
            break
        events.append(r.event)
    resolved = [i for i, e in enumerate(events) if type(e).__name__ == "TurnResolved" and e.source == "game"]
    stopped = events[:resolved[1] + 1]  # the game's end as its shell writes it after 2 turns of round 1
    ended = stamped(SessionEnded(reason="interrupted", detail="SIGINT", rounds_played=0, round=0, turns_in_round=2),
                    session=events[0].session, source="game", seq=stopped[-1].seq + 1, time_ns=stopped[-1].time_ns + 1)
    for name, evs in (("cut.mcap", events), ("stopped0.mcap", stopped + [ended])):
        w = EventLogWriter(root / name, chunk_size=2048)
        for i, e in enumerate(evs):
            w.write(event_key(e.session, e.source, type(e).__name__), encode_event(e), log_time_ns=10**18 + i,
                    sequence=e.seq)
        w.close()
    chunks = scan(root / "cut.mcap").chunks
    data = (root / "cut.mcap").read_bytes()
    (root / "cut.mcap").write_bytes(data[:chunks[-1].offset + chunks[-1].length])
    spec = json.loads((root / "policies" / "blind" / "game-00.json").read_text())
    spec.update(rounds=0, visits=[0] * len(spec["visits"]), q=[[0.0] * len(row) for row in spec["q"]])
    (root / "zero.json").write_text(json.dumps(spec))


def _read_only(case: Case, root: Path) -> tuple[str, Path]:
    """Where `case` runs read-only, for the zygote's command (cli_zygote._read_only: a mount namespace of the
    command's own, seen by it alone): an empty read-only tmpfs on ./ro, or the fixtures' folder `case.readonly`
    bound read-only, its files kept. (Each was a `python -m pairplay` under `unshare --mount`: 22 interpreters'
    start and import, ~15 s of CPU, for what the command says and does.)"""
    if isinstance(case.readonly, str):
        return "bind", root / case.readonly
    return "tmpfs", root / "ro"


def _run(case: Case, template: Path, base: Path, zygote: Zygote) -> Case:
    root = base / case.name.replace(" ", "_").replace("'", "").replace("/", "_")
    shutil.copytree(template, root)
    case.before = _snapshot(root)
    try:
        case.result = zygote.run(case.args, root, timeout=300,
                                 read_only=_read_only(case, root) if case.readonly else None)
    except subprocess.TimeoutExpired as hung:  # a verb that hangs on a mistake fails its row, not the table
        case.result = subprocess.CompletedProcess(hung.cmd, None, str(hung.stdout), f"hung: {hung}")
    case.after = _snapshot(root)
    return case


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    template = tmp_path_factory.mktemp("template")
    _fixtures(template)
    base = tmp_path_factory.mktemp("cases")
    todo = [c for c in CASES if CAN_UNSHARE or not c.readonly]
    with Zygote(env=ENV, scratch=tmp_path_factory.mktemp("zygote")) as zygote, ThreadPoolExecutor(4) as pool:
        # what pairplay's import printed would have been a line more on every case's stderr
        assert zygote.import_output == "" and zygote.threads == 1, (zygote.import_output, zygote.threads)
        done = list(pool.map(lambda c: _run(c, template, base, zygote), todo))
    TAKEN.close()
    return {c.name: c for c in done}


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_a_mistake_gets_one_line_and_changes_nothing(case, ran):
    if case.readonly and not CAN_UNSHARE:
        pytest.skip("needs root for a read-only mount")
    got = ran[case.name]
    r = got.result
    lines = r.stderr.strip().splitlines()
    assert r.returncode == case.code, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr + r.stdout, r.stderr
    assert len(lines) == 1, r.stderr
    verb = " ".join(case.args[:2] if case.args[0] in ("protocol", "participant") else case.args[:1])  # its action too
    assert lines[0].startswith(f"pairplay {verb}: ") and case.expect in lines[0], lines[0]
    assert bad_options(verb.split(), lines[0]) == [], lines[0]  # what it says to type exists (tests/hints.py)
    assert r.stdout == "", r.stdout  # refused before any work: no line before the refusal
    assert got.after == got.before, "files changed: " + str(set(got.after.items()) ^ set(got.before.items()))


def test_ctrl_c_during_a_study_is_one_line_exit_130_and_leaves_nothing(tmp_path):
    import signal
    import time
    study = subprocess.Popen([sys.executable, "-m", "pairplay", "study", "--quiet", "--out", "report"], cwd=tmp_path,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".report.*.tmp")) and time.monotonic() < deadline:  # the study is under way
        time.sleep(0.05)
    time.sleep(0.3)
    study.send_signal(signal.SIGINT)
    out, err = study.communicate(timeout=30)
    assert study.returncode == 130, (out, err)
    assert err.strip().splitlines() == ["pairplay study: interrupted (Ctrl-C); nothing more was written"], err
    assert list(tmp_path.iterdir()) == []  # no half report, no temporary folder


def test_help_shows_every_default_and_version_is_printed(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "1000")  # one line per option
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    from pairplay import __version__
    assert capsys.readouterr().out.strip() == f"pairplay {__version__}"
    for verb, flag, shown in (("session", "--rounds", "20"), ("session", "--seed", "0"), ("replay", "--speed", "1"),
                              ("session", "--game-index", "0"), ("session", "--algorithm", "q-learning"),
                              ("view", "--grpc-port", "9876"), ("study", "--games", "10"),
                              ("run", "--out", "recordings"), ("bench", "--only", "core")):
        with pytest.raises(SystemExit):
            main([verb, "--help"])
        lines = capsys.readouterr().out.splitlines()
        at = max(i for i, line in enumerate(lines) if line.lstrip().startswith(f"{flag} "))
        own = lines[at]  # the option's entry: its line and the help below it, up to the next option
        for line in lines[at + 1:]:
            if not line.startswith(" " * 8) or line.lstrip().startswith("-"):
                break
            own += " " + line.strip()
        assert "default" in own and shown in own, (verb, flag, own)


def _group_members(pgid: int) -> list[int]:
    """Live pids in process group `pgid` (from /proc; zombies excluded)."""
    members = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            members.append(int(stat.parent.name))
    return members


@pytest.mark.parametrize("verb", ["study", "sweep"])
def test_ctrl_c_at_a_terminal_reaches_every_worker_yet_prints_one_line_and_leaves_no_process(tmp_path, verb):
    """A terminal's Ctrl-C goes to the whole process group, the study's figure process and the
    sweep's workers included: they ignore it, the parent stops them, one line, exit 130."""
    import signal
    import time
    grid = tmp_path / "grid.toml"
    grid.write_text('seeds = 4\n[study]\npersonas = "blind,deaf"\ngames = 2\nrounds = 400\neval_rounds = 50\n'
                    '[grid]\ntrained_updates = [50, 40]\n')
    args = {"study": ["study", "--quiet", "--out", "report"],
            "sweep": ["sweep", str(grid), "--workers", "2", "--quiet", "--out", "swept"]}[verb]
    # the study with an empty numba cache: the Ctrl-C comes while its kernels compile
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", *args], cwd=tmp_path, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.monotonic() + 60
    while len(_group_members(proc.pid)) < 2 and time.monotonic() < deadline:  # its children have started
        time.sleep(0.05)
    time.sleep(1.0)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, (out, err)
    assert "Traceback" not in err, err
    assert err.strip().splitlines() == [f"pairplay {verb}: interrupted (Ctrl-C); nothing more was written"], err
    deadline = time.monotonic() + 10
    while _group_members(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _group_members(proc.pid) == []
    # no half report; a sweep keeps the cells it finished (it resumes from them)
    assert {p.name for p in tmp_path.iterdir()} - {"grid.toml", "numba-cache", "swept"} == set()


FINALIZERS = {  # a finalizer the garbage collector runs in the main thread, as the signal comes
    "__del__": "class Thing:\n    def __del__(self):\n        signal_and_work()\n"
               "def drop():\n    Thing()\n",
    "WeakSet._remove": "import weakref\nclass Noisy(set):\n    def discard(self, item):\n"
                       "        signal_and_work()\n        super().discard(item)\n"
                       "class Thing:\n    pass\n"
                       "held = weakref.WeakSet()\nheld.data = Noisy()\n"  # _remove calls data.discard
                       "def drop():\n    held.add(Thing())\n",
    "weakref.finalize": "import weakref\nclass Thing:\n    pass\n"
                        "def drop():\n    weakref.finalize(Thing(), signal_and_work)\n",
}


HANDLERS = {  # a handler that raises KeyboardInterrupt, installed
    "command": "from pairplay.cli.interrupts import DeferredInterrupt\nDeferredInterrupt().install()\n",
    "session's second Ctrl-C": "import threading\nfrom pairplay.services.bus import stop_on_signals\n"
                               "stop = threading.Event()\nstop_on_signals(stop)\n"
                               "os.kill(os.getpid(), signal.SIGINT)\nassert stop.wait(5)\n",
}


@pytest.mark.parametrize("handler", HANDLERS)
@pytest.mark.parametrize("kind", FINALIZERS)
def test_a_ctrl_c_inside_a_finalizer_is_not_swallowed(tmp_path, kind, handler):
    """A KeyboardInterrupt raised in a finalizer is printed as "Exception ignored" and swallowed: a study
    interrupted as the collector ran a WeakSet's callback went on and exited 0 (CI, fresh clone of 61bc185).
    The command's handler holds a signal that comes in one and delivers it once the finalizer is left."""
    script = tmp_path / "fin.py"
    script.write_text(
        "import os, signal, time\n"
        "def signal_and_work():\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "    for _ in range(100_000):\n"  # the handler runs here, inside the finalizer
        "        pass\n"
        + FINALIZERS[kind] + HANDLERS[handler] +
        "try:\n"
        "    drop()\n"  # the interrupt may land anywhere once the finalizer is left: here or in the sleep,
        "    time.sleep(120)\n"  # which it wakes (it waited for the sleep's end: 5 s a test)
        "    print('not interrupted')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted')\n")
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert r.stdout.splitlines() == ["interrupted"], (r.stdout, r.stderr)
    assert "Exception ignored" not in r.stderr, r.stderr


def test_a_ctrl_c_inside_numbas_compiler_waits_for_the_compile_then_interrupts(tmp_path):
    """llvmlite calls back into Python while it compiles: a KeyboardInterrupt there is swallowed
    (the run went on and exited 0) or leaves native objects half-built. The command's handler holds
    a Ctrl-C that comes while the main thread holds numba's compiler lock and delivers it after."""
    script = tmp_path / "hold.py"
    script.write_text(
        "import os, signal, time\n"
        "from numba.core.compiler_lock import global_compiler_lock\n"
        "from pairplay.cli.interrupts import DeferredInterrupt\n"
        "DeferredInterrupt().install()\n"
        "try:\n"
        "    with global_compiler_lock:\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "        time.sleep(0.3)\n"
        "        print('compile finished', flush=True)\n"
        "    time.sleep(120)\n"  # the interrupt wakes it (it waited for the sleep's end)
        "    print('not interrupted')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted after the compile')\n")
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert r.stdout.splitlines() == ["compile finished", "interrupted after the compile"], (r.stdout, r.stderr)

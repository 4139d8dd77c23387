"""The public Python API says a caller's mistake in one line, and the README's script runs as written.

A new user's trial (README "Scripting pairplay from Python") met raw errors from deep inside for
ordinary mistakes: read_log("nope.mcap") a FileNotFoundError, users_from_policies(paths) and
combine(["x"]) AttributeErrors, run_study(StudySettings(rounds="20")) a comparison's TypeError (now refused
by StudySettings itself, naming it),
fold_events([1, 2]) an empty fold, run_study into a folder of an earlier run "--force replaces"
(in Python the argument is force=True). Every function of `pairplay.API` gets mistakes here
(pairplay/arguments.py's rule: a UserError, one line, what and where; the wrong kind also a
TypeError, the right kind unusable also a ValueError). The README's script is run from its text,
as a script, over an earlier study's folder (its second run replaced nothing before force=True), so it
cannot drift.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import pairplay
from pairplay.errors import OutputError, UserError

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "recordings" / "samples"
REC = SAMPLES / "sim-helmut-fmt2.mcap"


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """What a script has in hand: a read policy, users, a merge, a recording's turns; a folder to write in."""
    tmp = tmp_path_factory.mktemp("api")
    policy = pairplay.rebuild_recording(REC).policy
    users, _ = pairplay.users_from_policies([policy], seed=0)
    (tmp / "earlier").mkdir()
    (tmp / "earlier" / "notes.txt").write_text("an earlier run's\n")
    (tmp / "policy.json").write_text("{}\n")
    (tmp / "text.mcap").write_text("not a recording\n")
    return SimpleNamespace(tmp=tmp, policy=policy, users=users, merged=pairplay.combine(users),
                           turns=pairplay.read_turns(REC))


S, C = pairplay.StudySettings, pairplay.SessionConfig
SIM = dict(session="api", seed=1, participant="sim:blind", persona="blind")

# (function, call, what the error is besides a UserError, words its line holds)
CASES = [
    ("read_log", lambda m: pairplay.read_log(m.tmp / "nope.mcap"), ValueError, "no such recording"),
    ("read_log", lambda m: pairplay.read_log(m.tmp), ValueError, "a folder, not a recording"),
    ("read_log", lambda m: pairplay.read_log(None), TypeError, "path must be a path"),
    ("read_log", lambda m: pairplay.read_log(42), TypeError, "(pairplay.read_log(path))"),
    ("verify_recording", lambda m: pairplay.verify_recording(m.tmp / "nope.mcap"), ValueError, "no such recording"),
    ("verify_recording", lambda m: pairplay.verify_recording(m.tmp / "text.mcap"), ValueError, "not an MCAP file"),
    ("verify_recording", lambda m: pairplay.verify_recording(None), TypeError, "(pairplay.verify_recording(path))"),
    ("read_turns", lambda m: pairplay.read_turns(None), TypeError, "(pairplay.read_turns(path))"),
    ("rebuild_recording", lambda m: pairplay.rebuild_recording(3), TypeError, "(pairplay.rebuild_recording(path))"),
    ("recover", lambda m: pairplay.recover(None), TypeError, "(pairplay.recover(path))"),
    ("recover", lambda m: pairplay.recover(REC, m.tmp / "r.mcap", force="no"), TypeError, "force must be True or False"),
    ("fold_events", lambda m: pairplay.fold_events([1, 2]), TypeError, "events[0] must be an event"),
    ("fold_events", lambda m: pairplay.fold_events(None), TypeError, "(pairplay.fold_events(events))"),
    ("fold_events", lambda m: pairplay.fold_events(pairplay.read_log(REC).events), TypeError,
     "e.event for e in log.events"),
    ("read_policy", lambda m: pairplay.read_policy(None), TypeError, "(pairplay.read_policy(path))"),
    ("read_policy", lambda m: pairplay.read_policy(m.tmp / "nope.json"), ValueError, "cannot read"),
    ("write_policy", lambda m: pairplay.write_policy(m.policy, m.tmp / "p.json"), TypeError,
     "(pairplay.write_policy(path))"),
    ("write_policy", lambda m: pairplay.write_policy(m.tmp / "p.json", "x"), TypeError, "value must be a PolicyFile"),
    ("write_policy", lambda m: pairplay.write_policy(m.tmp / "policy.json", m.policy), OutputError,
     "exists; force=True replaces it"),
    ("read_user_model", lambda m: pairplay.read_user_model(None), TypeError, "(pairplay.read_user_model(path))"),
    ("users_from_policies", lambda m: pairplay.users_from_policies([], seed=0), ValueError, "policies is empty"),
    ("users_from_policies", lambda m: pairplay.users_from_policies([REC], seed=0), TypeError,
     "read it first: pairplay.read_policy(path)"),
    ("users_from_policies", lambda m: pairplay.users_from_policies([m.policy], seed=True), TypeError,
     "seed must be an integer, got bool"),
    ("users_from_policies", lambda m: pairplay.users_from_policies([m.policy], 0, exclude=[m.policy.participant]),
     ValueError, "excluded"),
    ("extract_info", lambda m: pairplay.extract_info(None), TypeError, "(pairplay.extract_info(policies))"),
    ("extract_info", lambda m: pairplay.extract_info(np.full(24, 88)), ValueError, "outside 0..87"),
    ("combine", lambda m: pairplay.combine(["x"]), TypeError, "users[0] must be a User"),
    ("combine", lambda m: pairplay.combine([]), ValueError, "users is empty"),
    ("combine", lambda m: pairplay.combine(None), TypeError, "(pairplay.combine(users))"),
    ("combined_policy_file", lambda m: pairplay.combined_policy_file(m.users, m.users, [], 0), TypeError,
     "merged must be a Combined"),
    ("combined_policy_file", lambda m: pairplay.combined_policy_file(m.merged, m.users, [], 1.0), TypeError,
     "seed must be an integer"),
    ("fit_user", lambda m: pairplay.fit_user([], m.turns.config.observed_source), TypeError, "obs must be Observations"),
    ("fit_user", lambda m: pairplay.fit_user(m.turns.observations, "bogus"), ValueError, "source must be one of"),
    ("run_arms", lambda m: pairplay.run_arms("blind", [], [0], 10), TypeError, "persona must be a Persona"),
    ("run_study", lambda m: pairplay.run_study({"seed": 1}, m.tmp / "s"), TypeError, "args must be a StudySettings"),
    # a setting alone is refused where it is made, naming StudySettings (it was said by run_study as "(rounds)")
    ("StudySettings", lambda m: S(rounds="20"), TypeError,
     "must be an integer, got str '20' (pairplay.StudySettings(rounds))"),
    ("StudySettings", lambda m: S(rounds=0), ValueError, "must be at least 1, got 0 (pairplay.StudySettings(rounds))"),
    ("StudySettings", lambda m: S(personas=""), ValueError, "names no persona"),
    ("StudySettings", lambda m: S(seed=1.5), TypeError, "must be an integer, got float 1.5 (pairplay.StudySettings(seed))"),
    ("StudySettings", lambda m: S(personas=["blind"]), TypeError, "comma-separated"),
    ("StudySettings", lambda m: S(train_only=1), TypeError, "true or false"),
    ("StudySettings", lambda m: S(personas="nobody"), ValueError, "unknown persona 'nobody'"),
    ("StudySettings", lambda m: S(psi=float("nan")), ValueError, "must be between 0 and 1, got nan (pairplay.StudySettings(psi))"),
    ("StudySettings", lambda m: S(algorithm="sarsa"), ValueError, "(pairplay.StudySettings(algorithm))"),
    # what depends on the whole study is run_study's (the speed-up's snapshots every 10 rounds)
    ("run_study", lambda m: pairplay.run_study(S(personas="blind,deaf", rounds=5), m.tmp / "s"), ValueError,
     "must be at least 10 when the speed-up runs"),
    ("run_study", lambda m: pairplay.run_study(S(personas="blind", games=1, rounds=10), None), TypeError,
     "(pairplay.run_study(out))"),
    ("run_study", lambda m: pairplay.run_study(S(personas="blind", games=1, rounds=10), m.tmp / "earlier"),
     OutputError, "exists and is not empty; force=True replaces"),
    ("run_session", lambda m: pairplay.run_session({"session": "x"}, m.tmp / "x.mcap"), TypeError,
     "config must be a SessionConfig"),
    # a field alone is refused where the config is made, naming SessionConfig (it was taken, and refused only by
    # run_session as "config.rounds: ...": SessionConfig's __post_init__, schemas/public.py)
    ("SessionConfig", lambda m: C(**SIM, rounds="20"), TypeError,
     "rounds must be an integer, got str '20' (pairplay.SessionConfig(rounds))"),
    ("SessionConfig", lambda m: C(**SIM, rounds=True), TypeError,
     "rounds must be an integer, got bool True (pairplay.SessionConfig(rounds))"),
    ("SessionConfig", lambda m: C(**SIM, rounds=-1), ValueError, "rounds must be >= 1, got -1 (pairplay.SessionConfig(rounds))"),
    ("SessionConfig", lambda m: C(**SIM, rounds=5, policy_actions=[0, "a"]), TypeError,
     "policy_actions[1]: must be an integer, got text (pairplay.SessionConfig(policy_actions))"),
    ("SessionConfig", lambda m: C(**SIM, rounds=5, turn_back_ms=float("inf")), ValueError,
     "turn_back_ms must be 0..60000, got inf (pairplay.SessionConfig(turn_back_ms))"),
    ("SessionConfig", lambda m: C(**SIM, rounds=5, ignore_rule="never"), ValueError,
     "(pairplay.SessionConfig(ignore_rule))"),
    ("SessionConfig", lambda m: C(**(SIM | {"seed": np.int64(3)}), rounds=5), TypeError,
     "seed cannot be int64 np.int64(3): give a plain Python value"),
    ("run_session", lambda m: pairplay.run_session(C(**SIM, rounds=5), None), TypeError,
     "(pairplay.run_session(path))"),
]


@pytest.mark.parametrize("function, call, kind, words", CASES,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_a_mistake_is_one_line_saying_what_and_where(made, function, call, kind, words):
    with pytest.raises(UserError) as caught:
        call(made)
    err = caught.value
    line = str(err)
    assert isinstance(err, kind), f"{type(err).__name__} is no {kind.__name__}: {line}"
    assert "\n" not in line and words in line, line
    assert "--" not in line, f"a verb's option in the Python API's words: {line}"  # force=True, not --force
    # where: the function and argument, the file or the setting (a JSON file's errors begin with the file)
    assert err.where or line.startswith(f"{made.tmp}/"), f"says no where: {line}"


def test_every_function_of_the_api_gets_a_mistake():
    functions = {name for name in pairplay.API if not isinstance(getattr(pairplay, name), type)}
    assert functions - {c[0] for c in CASES} == set()


def test_the_functions_still_work(made):
    """The checks refuse mistakes only: what the README does goes through (a policy's array, a tuple of users)."""
    assert pairplay.extract_info(made.users[0].policy).info.compared_states == 23
    assert len(pairplay.combine(tuple(made.users)).policy) == 24
    assert pairplay.fold_events(e.event for e in pairplay.read_log(REC).events).whole_rounds()
    assert pairplay.combined_policy_file(made.merged, made.users, ["a"], np.int64(1)).seed == 1


def test_gym_refuses_a_bool_for_an_action():
    """env.step(True) was action 1 and the vector env took a bool array, where reset(seed=True) was refused."""
    import gymnasium
    import pairplay.gym  # noqa: F401  (registers pairplay/Memory-v0)
    env = gymnasium.make("pairplay/Memory-v0", persona="deaf")
    env.reset(seed=1)
    for action in (True, False, np.bool_(True)):
        with pytest.raises(ValueError, match="integers 0..87"):
            env.step(action)
    env.step(np.int64(35))  # numpy's integers are integers
    vec = gymnasium.make_vec("pairplay/Memory-v0", num_envs=4, vectorization_mode="vector_entry_point", persona="blind")
    vec.reset(seed=0)
    for actions in (np.array([True, False, True, True]), [True, 1, 2, 3]):
        with pytest.raises(ValueError, match="one per game"):
            vec.step(actions)
    vec.step(np.array([1, 2, 3, 4]))
    for seed in (True, np.bool_(False)):
        with pytest.raises(TypeError):
            env.reset(seed=seed)


def readme_script() -> str:
    section = (ROOT / "README.md").read_text().split("## Scripting pairplay from Python", 1)[1].split("\n## ", 1)[0]
    return re.search(r"```python\n(.*?)```", section, re.S)[1]


def test_the_readme_script_runs_as_written_over_an_earlier_study(tmp_path, pairplay_cli):
    """From a clone's folder (here: one holding only recordings/samples), saved as a file and run with
    `python script.py`, as the README says: run_study draws its figures in worker processes that import the
    script again, so without its `__main__` guard it failed (BrokenProcessPool; a researcher's trial). Its
    study folder already holds an earlier study (a small one: the script's second run stopped on "exists
    and is not empty" before force=True; any earlier study's folder is refused so), which it replaces."""
    shutil.copytree(SAMPLES, tmp_path / "recordings" / "samples")
    (tmp_path / "script.py").write_text(readme_script())
    earlier = pairplay_cli("study", "--quiet", "--personas", "blind,deaf", "--games", "1", "--rounds", "10",
                           "--eval-rounds", "10", "--reuse-seeds", "1", "--out", "out/blind-deaf", cwd=tmp_path)
    assert earlier.returncode == 0, earlier.stderr
    assert len(list((tmp_path / "out" / "blind-deaf" / "policies").rglob("*.json"))) == 2
    done = subprocess.run([sys.executable, "script.py"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "'focus'" in done.stdout and "learned/oracle" in done.stdout, done.stdout
    assert (tmp_path / "out" / "blind-deaf" / "report.md").is_file()
    assert len(list((tmp_path / "out" / "blind-deaf" / "policies").rglob("*.json"))) == 6  # 2 personas x 3 games


def test_run_study_refuses_an_out_inside_a_peoples_study_folder(tmp_path):
    """trial34 M: `pairplay study --out S1/policies` is refused, but `run_study(..., "S1/policies")` wrote a report,
    figures and a policies/ folder beside the study's policy files. Refused before any work, as the verb is."""
    import pairplay
    from pairplay.errors import OutputError
    from pairplay.replay.studyroot import JOURNAL
    from pairplay.schemas.study import STUDY_FILE

    folder = tmp_path / "S1"
    (folder / "policies").mkdir(parents=True)
    (folder / JOURNAL).write_text("")
    (folder / STUDY_FILE).write_text("")
    with pytest.raises(OutputError) as err:
        pairplay.run_study(pairplay.StudySettings(personas="blind", games=1, rounds=10), folder / "policies", force=True)
    assert "inside a people's study folder" in str(err.value) and "only `pairplay protocol` writes" in str(err.value)
    assert sorted(p.name for p in (folder / "policies").iterdir()) == []


def test_run_study_does_not_load_the_study_data_layer(tmp_path):
    """The study-folder check in run_study imported replay/copies.py, and with it the study's data layer (~44
    modules): the simulated study's peak rose from 191-192 to 196-199 MiB (issue 16's goal is 200). Its check asks
    the light replay/studyroot.py."""
    import subprocess
    import sys

    code = ("import sys, pairplay; pairplay.run_study(pairplay.StudySettings(personas='blind', games=1, rounds=10), "
            f"{str(tmp_path / 'out')!r}); print(sorted(m for m in sys.modules if m.startswith('pairplay.replay.')))")
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    assert "pairplay.replay.studydata" not in ran.stdout and "pairplay.replay.copies" not in ran.stdout, ran.stdout

"""Every JSON or TOML file a user gives is read the same way: an editor's UTF-8 byte order mark is accepted
(it was "malformed at byte 0", the mark unnamed), and a versioned file of ours (policy, user model) without its
"format" field is refused in one line naming the field (the field's default filled it in: it was accepted).
A new user's trial; before, every case here failed."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest

from pairplay.errors import InputError
from pairplay.replay.rebuild import rebuild_recording
from pairplay.schemas import policy as policy_file
BOM = b"\xef\xbb\xbf"  # what Notepad puts first

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"


@pytest.fixture(scope="module")
def policy_bytes() -> bytes:
    return policy_file.FILE.encode(rebuild_recording(SAMPLE).policy)


def test_a_policy_file_with_a_byte_order_mark_is_read(tmp_path, policy_bytes):
    (tmp_path / "p.json").write_bytes(BOM + policy_bytes)
    (tmp_path / "q.json").write_bytes(policy_bytes)
    assert policy_file.read_policy(tmp_path / "p.json") == policy_file.read_policy(tmp_path / "q.json")


@pytest.mark.parametrize("kind", ["policy", "user-model"])
def test_a_versioned_file_without_format_is_refused_naming_the_field(tmp_path, policy_bytes, kind):
    from pairplay.schemas import usermodel
    if kind == "policy":
        data, reader = json.loads(policy_bytes), policy_file.FILE
    else:
        data, reader = {"version": 1}, usermodel.FILE
    data.pop("format", None)
    path = tmp_path / "x.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputError) as err:
        reader.read(path)
    assert str(err.value) == f'{path}: no "format" field: not a {kind} file'


def test_the_cli_refuses_a_policy_without_format_in_one_line(tmp_path, policy_bytes, capsys):
    from pairplay.cli.main import main

    data = json.loads(policy_bytes)
    data.pop("format")
    (tmp_path / "a.json").write_text(json.dumps(data))
    (tmp_path / "b.json").write_bytes(BOM + policy_bytes)
    assert main(["combine", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "-o", str(tmp_path / "m.json")]) == 2
    [line] = capsys.readouterr().err.splitlines()
    assert 'no "format" field' in line and "a.json" in line, line


def test_text_inputs_with_a_byte_order_mark_are_read(tmp_path):
    from pairplay.report.sweep import read_grid
    from pairplay.schemas.study import example_text, load_study
    from pairplay.services.bus import read_config_file
    from pairplay.services.robot.backends import load_robot_config
    from pairplay.services.robot.calibration import load_calibration

    files = {
        "study.toml": example_text().encode(),
        "grid.toml": b'seeds = 1\n[study]\npersonas = "blind"\n',
        "calibration.json": resources.files("pairplay.services.robot").joinpath("calibration_default.json").read_bytes(),
        "robot.json": b"{}",
        "zenoh.json5": b"{mode: 'peer'}",
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(BOM + data)
    assert load_study(tmp_path / "study.toml").study.id
    assert len(read_grid(tmp_path / "grid.toml").cells()) == 1
    assert load_calibration(tmp_path / "calibration.json") == load_calibration(None)
    assert load_robot_config(str(tmp_path / "robot.json")) == load_robot_config(None)
    assert read_config_file(str(tmp_path / "zenoh.json5")) == {"mode": "peer"}
    from pairplay.replay.studydata import _settings  # a study folder's settings.json, edited by hand (keys helper)
    (tmp_path / "settings.json").write_bytes(BOM + b'{"key_file": ""}')
    assert _settings(tmp_path / "settings.json") == {"key_file": ""}


def other_policy(policy_bytes: bytes, participant: str = "helmut"):
    """Another policy (by default another participant's): the sample's, its Q differing in one state."""
    import msgspec

    whole = policy_file.FILE.decode(policy_bytes)
    return msgspec.structs.replace(whole, participant=participant, q=[[v + 0.5 for v in whole.q[0]], *whole.q[1:]])


def test_a_merge_of_a_partial_policy_is_flagged_partial_and_said_once(tmp_path, policy_bytes, capsys):
    """A new user's trial: `combine` of a policy flagged partial (a session stopped early, a damaged recording)
    wrote a merged policy whose `partial` field was empty, and said nothing. A merge of any partial input is
    partial, naming that input and why, in the file and once on the console; the combiner service alike."""
    import msgspec

    from pairplay.cli.main import main
    from pairplay.schemas import events as ev
    from pairplay.services.combiner import CombinerLogic

    why = "interrupted (SIGINT) after 3 of 10 rounds"
    partial = msgspec.structs.replace(policy_file.FILE.decode(policy_bytes), partial=why)
    policy_file.write_policy(tmp_path / "a.json", partial)
    # two policies a participant (a merge weighs each by its profile, algorithm 3): ashley's a and b, helmut's c and d
    ashley = other_policy(policy_bytes, partial.participant)
    policy_file.write_policy(tmp_path / "b.json", msgspec.structs.replace(ashley, q=[[v + 2.0 for v in ashley.q[0]],
                                                                                 *ashley.q[1:]]))
    helmut = other_policy(policy_bytes)
    policy_file.write_policy(tmp_path / "c.json", helmut)
    policy_file.write_policy(tmp_path / "d.json", msgspec.structs.replace(helmut, q=[[v + 1.0 for v in helmut.q[0]],
                                                                                 *helmut.q[1:]]))
    files = [str(tmp_path / f"{n}.json") for n in "abcd"]
    assert main(["combine", *files, "-o", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    merged = policy_file.read_policy(tmp_path / "m.json")
    assert merged.partial == f"made of a partial policy: {tmp_path / 'a.json'} ({why})", merged.partial
    assert out.count("PARTIAL") == 1 and f"PARTIAL merge: {merged.partial}" in out, out
    # a warning about the result: on stderr too, -q or not (cli/main.py `warn`: -q hid it with the listing)
    assert main(["combine", *files, "-o", str(tmp_path / "m.json"), "--force", "-q"]) == 0
    out, err = capsys.readouterr()
    assert out == "" and err == f"pairplay combine: PARTIAL merge: {merged.partial}\n", (out, err)
    [answer] = CombinerLogic(tmp_path).handle(ev.CombineRequested(request_id="r", policies=["a.json", "b.json"],
                                                                  output_path="bus.json"))
    assert answer.ok and policy_file.read_policy(tmp_path / "bus.json").partial == f"made of a partial policy: a.json ({why})"
    # a partial policy of a participant left out takes no part
    assert main(["combine", *files, "--exclude", "ashley", "-o", str(tmp_path / "w.json")]) == 0
    assert "PARTIAL" not in capsys.readouterr().out and policy_file.read_policy(tmp_path / "w.json").partial == ""


def test_a_profile_of_a_partial_policy_says_it_is_partial_in_its_output_and_on_stderr(tmp_path, policy_bytes,
                                                                                      capsys):
    """A trial: `profile` of a policy a `rebuild --partial` made (`partial` set) said nothing, where `combine`
    flags its merge. Its output (often redirected to a file) and stderr name the input and why, once each."""
    import msgspec

    from pairplay.cli.main import main

    why = "lost 2 messages that do not decode"
    partial = msgspec.structs.replace(policy_file.FILE.decode(policy_bytes), partial=why)
    policy_file.write_policy(tmp_path / "a.json", partial)
    policy_file.write_policy(tmp_path / "c.json", other_policy(policy_bytes, "ashley"))  # a second of hers
    assert main(["profile", str(tmp_path / "a.json"), str(tmp_path / "c.json")]) == 0
    captured = capsys.readouterr()
    said = f"PARTIAL profile: made of a partial policy: {tmp_path / 'a.json'} ({why})"
    assert captured.out.count("PARTIAL") == 1 and said in captured.out, captured.out
    assert captured.err == f"pairplay profile: {said}\n", captured.err
    policy_file.write_policy(tmp_path / "a.json", policy_file.FILE.decode(policy_bytes), force=True)
    assert main(["profile", str(tmp_path / "a.json"), str(tmp_path / "c.json")]) == 0
    captured = capsys.readouterr()
    assert "PARTIAL" not in captured.out and captured.err == "", captured


# every verb that reads a policy file it is given (each reads it through schemas/policy.py): {a} the file tried
POLICY_READERS = [
    ["session", "--participant", "sim:deaf", "--algorithm", "fixed", "--policy", "{a}"],
    ["session", "--participant", "sim:deaf", "--algorithm", "pi-reuse", "--policy", "{a}"],
    ["combine", "{a}", "{b}"],
    ["profile", "{a}", "{c}"],
    ["counterfactual", str(SAMPLE), "--policy", "fixed:{a}", "--out", "{tmp}/cf"],
]


def _reader_id(v: list[str]) -> str:
    return " ".join(v[:4:3] if v[0] == "session" else v[:1])


@pytest.mark.parametrize("verb", POLICY_READERS, ids=_reader_id)
def test_a_policy_file_of_an_unknown_algorithm_is_refused_naming_the_file_and_the_value(tmp_path, policy_bytes,
                                                                                           capsys, verb):
    """A new user's trial: a policy file saying "algorithm": "banana" was taken by `session --algorithm fixed`
    (and combined, profiled, played) as a policy. Wherever a policy file is read (schemas/policy.py), an
    algorithm that is not one of ALGORITHMS is one line naming the file and the value, exit 2."""
    from pairplay.cli.main import main

    data = json.loads(policy_bytes)
    data["algorithm"] = "banana"
    (tmp_path / "a.json").write_text(json.dumps(data))
    policy_file.write_policy(tmp_path / "b.json", other_policy(policy_bytes))
    policy_file.write_policy(tmp_path / "c.json", other_policy(policy_bytes, "ashley"))  # a second of hers
    args = [a.format(a=tmp_path / "a.json", b=tmp_path / "b.json", c=tmp_path / "c.json", tmp=tmp_path)
            for a in verb]
    assert main(args) == 2
    out, err = capsys.readouterr()
    [line] = err.splitlines()
    assert f"{tmp_path / 'a.json'}: " in line and "algorithm 'banana' is not one of q-learning, " in line, line
    assert not (tmp_path / "cf").exists()


EMPTY_INPUTS = [
    ["session", "--participant", "sim:deaf", "--algorithm", "fixed", "--policy", "{f}.json"],
    ["combine", "{f}.json", "-o", "{tmp}/m.json"],
    ["protocol", "check", "{f}.toml"],
    ["protocol", "init", "{tmp}/study", "--study", "{f}.toml"],
    ["sweep", "{f}.toml", "--out", "{tmp}/sweep"],
    ["robot", "--try", "1", "--robot-config", "{f}.json"],
    ["robot", "--try", "1", "--calibration", "{f}.json"],
    ["lab", "--participant", "human:p1", "--zenoh-config", "{f}.json5"],
    ["rebuild", "{f}.mcap", "--out", "{tmp}/rb"],
]


def _verb_id(v: list[str]) -> str:
    return " ".join(v[:2]) if v[0] == "protocol" else f"robot {v[-2]}" if v[0] == "robot" else v[0]


# a text input of blanks too (an MCAP file of blanks is not MCAP: said so, test_cli_mistakes)
@pytest.mark.parametrize("verb,blank", [pytest.param(v, b, id=f"{_verb_id(v)}-{name}")
                                        for v in EMPTY_INPUTS for b, name in ((b"", "0 bytes"), (BOM + b"\n \n", "blank"))
                                        if not (v[0] == "rebuild" and b)])
def test_an_empty_input_file_is_said_to_be_empty_naming_it(tmp_path, capsys, verb, blank):
    """A new user's trial: an empty --policy file said "Input data was truncated" (msgspec's words), an empty
    study file "Object missing required field `study`", an empty sweep file ran the default study with exit 0.
    Every JSON, TOML or MCAP input that is empty is one line naming the file, "the file is empty", exit 2,
    nothing written (schemas/jsonfile.py `empty`)."""
    from pairplay.cli.main import main

    args = [a.format(f=tmp_path / "in", tmp=tmp_path) for a in verb]
    given = next(a for a in args if a.startswith(str(tmp_path / "in")))
    Path(given).write_bytes(blank)
    assert main(args) == 2
    out, err = capsys.readouterr()
    [line] = err.splitlines()
    assert "the file is empty" in line and given in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == [Path(given).name]


def test_an_empty_user_model_file_is_said_to_be_empty(tmp_path):
    from pairplay.schemas import usermodel

    (tmp_path / "u.json").write_bytes(b"")
    with pytest.raises(InputError) as err:
        usermodel.read_user_model(tmp_path / "u.json")
    assert str(err.value) == f"{tmp_path / 'u.json'}: the file is empty"


def _greedy_changed(policy_bytes: bytes, tied: bool) -> tuple[dict, int]:
    """The sample's policy with the greedy action of its first learned state changed to another action of the
    highest Q (`tied`) or to one below it; and that state."""
    data = json.loads(policy_bytes)
    state = next(s for s, row in enumerate(data["q"]) if min(row) < max(row) and row.count(max(row)) > 1)
    row = data["q"][state]
    data["greedy"][state] = next(a for a, v in enumerate(row)
                                 if (v == max(row)) == tied and a != data["greedy"][state])
    return data, state


@pytest.mark.parametrize("verb", POLICY_READERS, ids=_reader_id)
def test_a_policy_whose_greedy_is_not_its_q_tables_is_refused_naming_the_state(tmp_path, policy_bytes, capsys, verb):
    """trial29 F5: a policy file whose greedy[s] is no argmax of its own q[s] was taken: combine and profile read
    greedy, pi-reuse reads q, so one file was two policies. Wherever a policy file is read (schemas/policy.py), one
    line naming the file and the state, exit 2."""
    from pairplay.cli.main import main

    data, state = _greedy_changed(policy_bytes, tied=False)
    (tmp_path / "a.json").write_text(json.dumps(data))
    policy_file.write_policy(tmp_path / "b.json", other_policy(policy_bytes))
    policy_file.write_policy(tmp_path / "c.json", other_policy(policy_bytes, "ashley"))
    args = [a.format(a=tmp_path / "a.json", b=tmp_path / "b.json", c=tmp_path / "c.json", tmp=tmp_path)
            for a in verb]
    assert main(args) == 2
    [line] = capsys.readouterr().err.splitlines()
    name = policy_file.STATE_NAMES[state]
    assert f"{tmp_path / 'a.json'}: " in line and f"greedy[{state}] ({name}): action " in line, line
    assert f"is not a best action of its Q-table's row q[{state}]" in line, line
    assert not (tmp_path / "cf").exists()


def test_a_greedy_action_tied_for_the_best_of_its_q_is_read(tmp_path, policy_bytes):
    """A tie is the writer's to break (a seeded draw): any action of the highest Q is the greedy one; and a merged
    policy's greedy is its rules', not its Q-table's (combine's output is read back)."""
    data, state = _greedy_changed(policy_bytes, tied=True)
    (tmp_path / "a.json").write_text(json.dumps(data))
    assert policy_file.read_policy(tmp_path / "a.json").greedy[state] == data["greedy"][state]
    data["algorithm"] = "combined"
    data["greedy"][state] = next(a for a, v in enumerate(data["q"][state]) if v < max(data["q"][state]))
    (tmp_path / "m.json").write_text(json.dumps(data))
    assert policy_file.read_policy(tmp_path / "m.json").algorithm == "combined"

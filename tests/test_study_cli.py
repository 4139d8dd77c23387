"""`pairplay study`, `profile` and `combine` from the command line, on real files."""

import json

import pytest

from pairplay.schemas.policy import read_policy
from pairplay.cli.main import main


@pytest.fixture(scope="module")
def study_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    assert main(["study", "--quiet", "--personas", "blind,deaf,tatiana", "--games", "2", "--rounds", "60",
                 "--eval-rounds", "5", "--reuse-seeds", "2", "--reuse-last", "10", "--out", str(out)]) == 0
    return out


def test_the_study_writes_its_report_folder(study_dir):
    for name in ("report.md", "curves.csv", "curves_summary.csv", "evaluation.csv", "profiles.csv",
                 "merged_evaluation.csv", "reuse.csv", "learning_curves.png", "evaluation.png", "profiles.png",
                 "merged.png", "reuse.png", "merged/blind+deaf.json", "merged/all.json"):
        assert (study_dir / name).stat().st_size > 0, name
    report = (study_dir / "report.md").read_text()
    assert "trained states: speech % / head %" in report
    for section in ("User information", "Merged policies", "Policy reuse speed-up", "Learning curves"):
        assert section in report
    rows = (study_dir / "curves.csv").read_text().splitlines()
    assert rows[0] == "persona,game,round,picks,inconsistent" and len(rows) == 1 + 3 * 2 * 60


def test_policy_files_hold_what_the_study_learned(study_dir):
    policy = read_policy(study_dir / "policies" / "deaf" / "game-01.json")
    assert policy.participant == "deaf" and policy.game == 1 and policy.rounds == 60
    assert policy.persona.hearing == 1 and len(policy.q) == 24 and len(policy.q[0]) == 88
    assert policy.config.epsilon_start == 0.9 and policy.algorithm == "q-learning"
    assert policy.reward_bonus == "correct"  # the default rule, stated in every file
    merged = read_policy(study_dir / "merged" / "blind+deaf.json")
    assert merged.algorithm == "combined" and merged.merged_from == ["blind", "deaf"] and len(merged.rules) == 24


def test_profile_and_combine_verbs(study_dir, tmp_path, capsys):
    assert main(["profile", str(study_dir / "policies")]) == 0
    out = capsys.readouterr().out
    assert "blind" in out and "deaf" in out and "tatiana" in out
    assert main(["profile", str(study_dir / "policies"), "--min-updates", "5"]) == 0
    out = capsys.readouterr().out
    assert "at least 5 times" in out and "blind" in out
    target = tmp_path / "bd.json"
    assert main(["combine", str(study_dir / "policies" / "blind"), str(study_dir / "policies" / "deaf"),
                 "-o", str(target)]) == 0
    merged = read_policy(target)
    assert merged.participant == "blind+deaf" and len(merged.greedy) == 24
    again = tmp_path / "again.json"
    assert main(["combine", str(study_dir / "policies" / "deaf"), str(study_dir / "policies" / "blind"),
                 "-o", str(again)]) == 0
    assert read_policy(again).greedy == merged.greedy  # the order of the inputs does not matter


def test_a_corrupt_policy_file_is_refused_with_its_reason(study_dir, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    good = json.loads((study_dir / "policies" / "blind" / "game-00.json").read_text())
    greedy = good["greedy"][3]
    good["greedy"][3] = 99
    bad.write_text(json.dumps(good))
    out = tmp_path / "merged.json"
    assert main(["combine", str(bad), str(study_dir / "policies" / "deaf"), "-o", str(out)]) == 2
    assert "greedy actions outside 0..87" in capsys.readouterr().err and not out.exists()
    good["greedy"][3] = greedy  # (an action in range, but not a best of q[3], is refused too: test_input_files.py)
    good["reward_bonus"] = "always"
    bad.write_text(json.dumps(good))
    assert main(["profile", str(bad)]) == 2
    assert "reward_bonus 'always'" in capsys.readouterr().err
    del good["reward_bonus"]  # a pairplay 0.1.0 file: SPEC's rule
    bad.write_text(json.dumps(good))
    assert read_policy(bad).reward_bonus == "consistent"
    bad.write_text('{"format": "pairplay.policy", "q": [')
    assert main(["profile", str(bad)]) == 2
    assert "corrupt" in capsys.readouterr().err


def test_unknown_personas_are_refused(capsys):
    assert main(["study", "--personas", "nobody"]) == 2
    assert "unknown persona" in capsys.readouterr().err


def test_a_reader_that_stops_early_loses_no_merged_policy(study_dir, tmp_path, monkeypatch):
    """`pairplay combine ... -o merged.json | head`: the file is written, no traceback."""
    sink = open(tmp_path / "sink", "w")

    class ClosedPipe:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            pass

        def fileno(self):
            return sink.fileno()

    monkeypatch.setattr("sys.stdout", ClosedPipe())
    out = tmp_path / "merged.json"
    assert main(["combine", str(study_dir / "policies" / "blind"), str(study_dir / "policies" / "deaf"),
                 "-o", str(out)]) == 0
    assert read_policy(out).merged_from
    sink.close()


def test_policies_learned_under_different_rewards_are_not_combined(study_dir, tmp_path, capsys):
    other = json.loads((study_dir / "policies" / "blind" / "game-00.json").read_text())
    other["reward_bonus"] = "consistent"
    path = tmp_path / "blind-spec.json"
    path.write_text(json.dumps(other))
    out = tmp_path / "merged.json"
    assert main(["combine", str(path), str(study_dir / "policies" / "deaf"), "-o", str(out)]) == 2
    assert "different reward rules (consistent, correct)" in capsys.readouterr().err and not out.exists()
    assert main(["combine", str(study_dir / "policies" / "blind"), str(study_dir / "policies" / "deaf"),
                 "-o", str(out)]) == 0
    assert read_policy(out).reward_bonus == "correct"


def test_the_combiner_service_refuses_what_combine_refuses(study_dir):
    from pairplay.schemas import events as ev
    from pairplay.services.combiner import CombinerLogic

    logic = CombinerLogic(study_dir)
    same, deaf = "policies/blind/game-00.json", "policies/deaf/game-00.json"
    [twice] = logic.handle(ev.CombineRequested(request_id="twice", policies=[same, same, deaf]))
    assert not twice.ok and "given twice" in twice.error and same in twice.error
    before = (study_dir / "report.md").read_bytes()
    both = [same, "policies/blind/game-01.json", deaf, "policies/deaf/game-01.json"]  # two each: profiles
    [over] = logic.handle(ev.CombineRequested(request_id="over", policies=both, output_path="report.md"))
    assert not over.ok and "exists" in over.error and (study_dir / "report.md").read_bytes() == before


def _files(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_a_forced_study_over_an_older_one_keeps_none_of_the_older_ones_files(tmp_path, capsys):
    """`study --force` into the folder of an older study kept the older one's files the new one does not
    write (policies, sections of personas not in it, the speed-up's tables): stale files that looked
    current. Now the folder holds what a fresh study of the same options writes, and the files that are
    not a study's (a researcher's notes) stay. Every file a study writes is one of STUDY_OUTPUTS."""
    from pairplay.outputs import is_owned
    from pairplay.report.study import STUDY_MANIFEST, STUDY_OUTPUTS

    small = ["--games", "1", "--rounds", "20", "--eval-rounds", "5", "--reuse-seeds", "1", "--quiet"]
    out, fresh = tmp_path / "study", tmp_path / "fresh"
    assert main(["study", *small, "--personas", "blind,deaf,tatiana", "--algorithm", "lspi", "--out", str(out)]) == 0
    older = _files(out)
    assert [f for f in older if not is_owned(f, STUDY_OUTPUTS)] == [STUDY_MANIFEST] and "speed.csv" in older
    (out / "notes.txt").write_text("the researcher's")
    (out / "policies" / "notes.txt").write_text("the researcher's")
    newer = ["study", *small[:small.index("--reuse-seeds")], *small[small.index("--reuse-seeds") + 2:], "--personas",
             "blind", "--train-only"]  # (no speed-up there: its --reuse-seeds would be refused)
    assert main([*newer, "--out", str(out), "--force"]) == 0
    assert main([*newer, "--out", str(fresh)]) == 0
    assert _files(out) == sorted(_files(fresh) + ["notes.txt", "policies/notes.txt"])
    assert not (out / "policies" / "deaf").exists()


SECTIONS = ("## Merged policies (algorithm 4, figure 6.6)", "## Policy reuse speed-up (algorithm 5)",
            "## Per-user pre-combination (future work 3)", "## Action-level profiles (future work 1)")


def _figures_missing(out):
    import re
    return [f for f in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", (out / "report.md").read_text()) if not (out / f).exists()]


def test_a_report_says_why_a_section_did_not_run(tmp_path, study_dir):
    """A study of one persona left the speed-up and the future-work sections out without a word and showed
    merged.png, which it never drew: each section is there, saying what it needs; no figure is missing."""
    out = tmp_path / "one"
    assert main(["study", "--quiet", "--personas", "blind", "--games", "1", "--rounds", "20", "--eval-rounds", "5",
                 "--out", str(out)]) == 0
    text = (out / "report.md").read_text()
    for heading in SECTIONS:
        body = text.split(heading + "\n", 1)[1].split("\n## ", 1)[0]
        assert "needs at least 2 personas" in body or "at least 2 personas to merge" in body, (heading, body)
    assert _figures_missing(out) == []
    several = (study_dir / "report.md").read_text()  # 3 personas of 2 games: future work needs 5
    assert several.count("needs at least 5 games per persona") == 2 and _figures_missing(study_dir) == []

"""`pairplay study --algorithm lspi`: LSPI policy files, the side-by-side comparison, profiles and merges."""

import csv

import pytest

from pairplay.cli.main import main
from pairplay.core.policies import LSPI_Q_MEANING
from pairplay.schemas.policy import read_policy


@pytest.fixture(scope="module")
def lspi_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("lspi-study")
    assert main(["study", "--quiet", "--algorithm", "lspi", "--personas", "blind,deaf", "--games", "2",
                 "--rounds", "40", "--eval-rounds", "5", "--reuse-seeds", "1", "--reuse-last", "10",
                 "--out", str(out)]) == 0
    return out


def test_lspi_policy_files_say_what_their_q_is(lspi_dir):
    policy = read_policy(lspi_dir / "policies" / "blind" / "game-01.json")
    assert policy.algorithm == "lspi" and policy.q_meaning == LSPI_Q_MEANING
    assert policy.lspi.improve_every == 10 and policy.lspi.gamma == 0.0 and policy.rounds == 40
    assert sum(policy.visits) > 100 and any(any(v != 0 for v in row) for row in policy.q)


def test_the_report_puts_lspi_beside_q_learning(lspi_dir):
    rows = list(csv.reader(open(lspi_dir / "speed.csv")))
    assert rows[0][:4] == ["persona", "focus", "rounds to 1.10x oracle: q-learning", "rounds to 1.10x oracle: lspi"]
    assert [r[0] for r in rows[1:]] == ["blind", "deaf"]
    report = (lspi_dir / "report.md").read_text()
    assert "LSPI beside Q-learning" in report and "online LSPI (algorithm 2" in report
    assert "--algorithm lspi" in report and (lspi_dir / "speed.png").stat().st_size > 0


def test_profiles_and_merges_take_lspi_policies(lspi_dir, tmp_path, capsys):
    assert main(["profile", str(lspi_dir / "policies")]) == 0
    assert "blind" in capsys.readouterr().out
    target = tmp_path / "bd.json"
    assert main(["combine", str(lspi_dir / "policies" / "blind"), str(lspi_dir / "policies" / "deaf"),
                 "-o", str(target)]) == 0
    merged = read_policy(target)
    assert merged.algorithm == "combined" and merged.merged_from and len(merged.rules) == 24


def test_bad_lspi_settings_are_one_line_on_stderr(tmp_path, capsys):
    with pytest.raises(SystemExit) as stopped:  # refused by the option's parser (cli/args.py), before any work
        main(["study", "--quiet", "--algorithm", "lspi", "--lspi-every", "0", "--out", str(tmp_path / "x")])
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--lspi-every" in err and not (tmp_path / "x").exists()

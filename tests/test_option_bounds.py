"""Integer options that name a game's streams, or a number of processes or participants, are bounded in
the parser by the one constant the rest of pairplay uses (cli/args.py; schemas/session.py; core/rng.py).

Before: `pairplay session --game-index 99999999999999999999` passed `non_negative`, printed "bus
listening", then a 29-line traceback from core/rng.py's range check, and left recordings/<id>.mcap
holding no session (the id burnt); a study file's `seed = -1` was taken; `pairplay sweep --workers 1000`
was accepted (up to 1000 processes); `protocol register --count 100000` too, while the console's API
refused a count outside 1..50.
"""

from __future__ import annotations

import pytest

from pairplay.cli import args as options
from pairplay.cli.main import main


def _status(argv: list[str]) -> int:
    """main's exit status, argparse's refusals (SystemExit) included."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def test_the_game_index_range_is_core_rngs_and_the_session_configs():
    from pairplay.core.rng import GAME_INDEX_RANGE, game_seed
    from pairplay.schemas import session
    assert (0, options.GAME_INDEX_MAX) == GAME_INDEX_RANGE == session.GAME_INDEX_RANGE
    game_seed(5, "p1", options.GAME_INDEX_MAX)  # the top of the range runs
    with pytest.raises(ValueError):
        game_seed(5, "p1", options.GAME_INDEX_MAX + 1)


@pytest.mark.parametrize("value", ["99999999999999999999", str(2**63), "-1"])
def test_a_game_index_out_of_range_is_refused_before_the_bus_starts(value, tmp_path, capsys):
    out = tmp_path / "recordings"
    assert _status(["session", "--participant", "sim:deaf", "--rounds", "1", "--game-index", value,
                 "--session", "g", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert "--game-index" in captured.err and captured.err.count("\n") == 1 and "Traceback" not in captured.err
    assert "bus listening" not in captured.out + captured.err and not out.exists()


def test_a_session_config_refuses_a_game_index_core_cannot_run():
    from pairplay.schemas.session import SessionConfig
    with pytest.raises(ValueError, match="game index must be 0..9223372036854775807"):
        SessionConfig(session="s", participant="sim:deaf", persona="deaf", seed=1, rounds=1, game_index=2**63)


@pytest.mark.parametrize("seed", ["-1", "18446744073709551616"])
def test_a_study_files_seed_is_in_the_seed_range(seed):
    from pairplay.schemas.study import StudyFileError, example_text, parse_study
    with pytest.raises(StudyFileError, match=r"\[study\] seed: must be 0..18446744073709551615"):
        parse_study(example_text().replace("seed = 0", f"seed = {seed}", 1), "s.toml")


def test_sweep_workers_are_bounded_by_the_cpus_in_the_parser_and_in_run_sweep(tmp_path, capsys):
    from pairplay.processes import check_workers, max_workers
    from pairplay.report.sweep import read_grid, run_sweep
    top = max_workers()
    assert top >= 2 and check_workers(top) == top
    grid = tmp_path / "g.toml"
    grid.write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 1\neval_rounds = 1\n')
    for n in ("1000", str(top + 1)):
        assert _status(["sweep", "--quiet", str(grid), "--workers", n, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"--workers: must be 1..{top}" in err and err.count("\n") == 1
    with pytest.raises(ValueError, match=f"workers must be 1..{top}"):
        run_sweep(read_grid(grid), tmp_path / "o", workers=1000)
    assert not (tmp_path / "o").exists()


def test_protocol_register_takes_the_consoles_bound(tmp_path, capsys):
    from pathlib import Path

    import pairplay.services.console as console
    from pairplay.replay.studydata import REGISTER_AT_ONCE
    folder = tmp_path / "study"
    assert main(["protocol", "init", str(folder), "--study", "thesis-ch7"]) == 0
    capsys.readouterr()
    for n in ("100000", str(REGISTER_AT_ONCE + 1), "0"):
        assert _status(["protocol", "register", str(folder), "--count", n]) == 2
        err = capsys.readouterr().err
        assert "--count" in err and err.count("\n") == 1
    assert main(["protocol", "register", str(folder), "--count", str(REGISTER_AT_ONCE)]) == 0
    assert len(capsys.readouterr().out.split()) == REGISTER_AT_ONCE
    page = (Path(console.__file__).parent / "static" / "console.html").read_text()
    assert f'id="register-count" type="number" min="1" max="{REGISTER_AT_ONCE}"' in page  # the page says it too


# A new user's trial (2026-12-01): a session config took nan in its learner schedule (only the learner
# refused it, after the session had started) and inf board times. (policy_actions of the wrong length stay
# the learner's refusal: tests/test_refusal.py needs a config the game plays and the learner refuses.)
BAD_CONFIGS = {
    "learner alpha_start nan": ({"learner": {"alpha_start": float("nan")}}, "alpha_start must be 0..1, got nan"),
    "learner epsilon_start 5": ({"learner": {"epsilon_start": 5.0}}, "epsilon_start must be 0..1, got 5"),
    "learner alpha_every 0": ({"learner": {"alpha_every": 0}}, "alpha_every must be 1..1000000000, got 0"),
    "turn_back_ms inf": ({"turn_back_ms": float("inf")}, "turn_back_ms must be 0..60000, got inf"),
    "ignore_window_ms nan": ({"ignore_window_ms": float("nan")}, "ignore_window_ms must be 0..60000, got nan"),
}


@pytest.mark.parametrize("case", list(BAD_CONFIGS))
def test_a_session_config_refuses_numbers_its_services_cannot_use(case):
    from pairplay.schemas.session import SessionConfig

    change, expected = BAD_CONFIGS[case]
    with pytest.raises(ValueError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        # (a board time where the config is made, its __post_init__; the learner's schedule by validate)
        SessionConfig(session="s", participant="sim:blind", persona="blind", seed=0, rounds=2, **change).validate()


def test_one_learner_range_check_serves_every_source():
    """The CLI's presets, a study file's overrides and a policy file's config all make a LearnerConfig:
    its one check (schemas/config.py LEARNER_RANGES) refuses out-of-range values wherever they come from."""
    import msgspec

    from pairplay.schemas.config import LEARNER_RANGES, LearnerConfig

    assert set(LEARNER_RANGES) == set(LearnerConfig.__struct_fields__)
    for rounds in (1, 5, 500):  # every preset of every length is in range
        LearnerConfig.human_phase1(rounds), LearnerConfig.human_phase2(rounds)
    with pytest.raises(ValueError, match="psi_decay must be 0..1"):
        msgspec.structs.replace(LearnerConfig(), psi_decay=1.5)
    with pytest.raises(msgspec.ValidationError, match="epsilon_min must be 0..1"):
        msgspec.convert({"epsilon_min": -0.1}, LearnerConfig)


def test_trained_updates_above_what_a_state_can_count_is_refused(tmp_path, capsys):
    """`pairplay study --trained-updates 1e23` (as an integer) ran the whole study on a threshold no
    state can meet, without a word; it is refused in one line, nothing written."""
    out = tmp_path / "study"
    assert _status(["study", "--trained-updates", str(10**23), "--games", "1", "--rounds", "10", "--eval-rounds",
                    "1", "--personas", "ashley,blind", "--reuse-seeds", "1", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--trained-updates" in err and "must be 0..9223372036854775807" in err and err.count("\n") == 1, err
    assert not out.exists()


def test_the_update_count_bound_is_the_studys():
    from pairplay.report.study import UPDATES_MAX
    assert options.UPDATES_MAX == UPDATES_MAX == 2**63 - 1


def test_profile_min_updates_above_what_a_state_can_count_is_refused(tmp_path, capsys):
    assert _status(["profile", str(tmp_path), "--min-updates", str(10**23)]) == 2
    err = capsys.readouterr().err
    assert "--min-updates" in err and "9223372036854775807" in err and err.count("\n") == 1, err

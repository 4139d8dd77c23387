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
    config = SessionConfig(session="s", participant="sim:deaf", persona="deaf", seed=1, rounds=1,
                           game_index=2**63)
    with pytest.raises(ValueError, match="game index must be 0..9223372036854775807"):
        config.validate()


@pytest.mark.parametrize("seed", ["-1", "18446744073709551616"])
def test_a_study_files_seed_is_in_the_seed_range(seed):
    from pairplay.schemas.study import StudyFileError, example_text, parse_study
    with pytest.raises(StudyFileError, match="study.seed: must be 0..18446744073709551615"):
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

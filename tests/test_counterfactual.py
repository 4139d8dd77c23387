"""Counterfactual replay (issue 18, item 4): the user fit, the model file, the verb and its refusals.

The fit must recover the persona that made a session; the tolerance is stated
per observed-card source (core/userfit.py, README "Counterfactual replay").
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pairplay.cli.main import main
from pairplay.core.counterfactual import Arm, run_arms, to_user_model
from pairplay.core.interpretation import memory_capacity, sees
from pairplay.core.personas import PERSONAS, persona
from pairplay.core.simulate import run_games
from pairplay.core.userfit import fit_user, memory_before, observations_from_trace, pooled
from pairplay.errors import OutputError
from pairplay.replay.turns import read_turns
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas import events as ev
from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.schemas.usermodel import (UserModelFileError, decode_user_model, encode_user_model,
                                        read_user_model, write_user_model)

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-helmut-fmt2.mcap"
FEATURES = ("focus", "hearing", "sight", "memory")


def _simulated(key: str, source: str, seeds=(101, 102), rounds: int = 20):
    p = persona(key)
    trace = run_games([p] * len(seeds), list(seeds), rounds, record="all", observed_source=source).trace
    return p, trace


def test_memory_replayed_on_the_picks_is_the_simulated_users_memory():
    # the fit's memory is the simulator's own rule replayed: its NIS and "from memory" are the trace's
    for key in ("frances", "vincent"):
        p, trace = _simulated(key, "intended")
        obs = observations_from_trace(trace)
        mem = memory_before(obs, np.array([memory_capacity(p.memory)]))[:, 0]
        order = np.lexsort((trace["step"], trace["game"]))
        covered2 = obs.covered & ~(1 << obs.first)
        nis = np.where(covered2 & ~mem, covered2 & ~mem, covered2)
        assert np.array_equal(nis, trace["nis"][order])
        assert np.array_equal((mem >> obs.match) & 1, trace["from_memory"][order])


@pytest.mark.parametrize("key", sorted(PERSONAS))
def test_fit_recovers_each_persona_from_its_simulated_sessions(key):
    # 2 games x 20 rounds of Q-learning, observed card = the intended card (the simulation's source):
    # focus and memory exact, sight up to the groups of table 6.1, hearing within one level, and
    # every true level inside its 95% set (40 of 40 cases over 5 seeds when this was written)
    p, trace = _simulated(key, "intended")
    fit = fit_user(observations_from_trace(trace), "intended")
    lv = fit.levels
    assert lv["focus"] == p.focus and lv["memory"] == p.memory
    assert (sees(lv["sight"]) == sees(p.sight)).all()
    assert abs(lv["hearing"] - p.hearing) <= 1
    for f in FEATURES:
        assert getattr(p, f) in fit.set95[f], (f, fit.set95)
    assert fit.lapse == 0.0  # the simulated user never leaves its model
    low, high = fit.fine["p_consider"][1:]
    assert low <= (p.focus - 1) * 0.2 <= high


@pytest.mark.parametrize("key", ["helmut", "vincent"])
def test_fit_from_first_pick_observations_keeps_the_truth_in_its_95_sets(key):
    # a person's source: the unaided pick is unseen, so focus and hearing can trade (the blind
    # Vincent hears speech only: only p x q is identified); the true levels stay in the 95% sets
    p, trace = _simulated(key, "first-pick", seeds=(201, 202))
    fit = fit_user(observations_from_trace(trace), "first-pick")
    for f in FEATURES:
        assert getattr(p, f) in fit.set95[f], (f, fit.levels, fit.set95)
    assert fit.levels["memory"] == p.memory and (sees(fit.levels["sight"]) == sees(p.sight)).all()
    assert abs(fit.levels["focus"] - p.focus) <= 1 and abs(fit.levels["hearing"] - p.hearing) <= 1


def test_sessions_pooled_are_each_their_own_game():
    # two sessions fitted together = the two games of one batch (memory starts empty in each)
    p, both = _simulated("wasim", "intended", seeds=(7, 8), rounds=10)
    parts = [observations_from_trace(_simulated("wasim", "intended", seeds=(s,), rounds=10)[1]) for s in (7, 8)]
    assert np.array_equal(fit_user(pooled(parts), "intended").grid,
                          fit_user(observations_from_trace(both), "intended").grid)


def test_the_committed_sample_recording_gives_helmut_back():
    turns = read_turns(SAMPLE)
    assert turns.config.persona == "helmut" and len(turns.picks_per_round) == 15
    fit = fit_user(turns.observations, turns.config.observed_source)
    helmut = persona("helmut")
    assert fit.levels["focus"] == helmut.focus and fit.levels["memory"] == helmut.memory
    for f in FEATURES:
        assert getattr(helmut, f) in fit.set95[f]
    considered, of = fit.counted  # the participant's own report agrees with the fit's p
    low, high = fit.fine["p_consider"][1:]
    assert low <= considered / of <= high


def test_a_scripted_person_off_the_model_gets_a_lapse_not_a_crash():
    turns = read_turns(SAMPLE.parent / "human-board-fmt2.mcap")
    fit = fit_user(turns.observations, turns.config.observed_source)
    assert fit.lapse > 0 and np.isfinite(fit.loglik)


def test_arms_share_seeds_and_the_oracle_beats_the_user_alone():
    p = persona("tatiana")
    from pairplay.core.counterfactual import oracle_policy, user_alone
    arms = [Arm("alone", "fixed", LearnerConfig(), user_alone()), Arm("oracle", "fixed", LearnerConfig(), oracle_policy(p, 0))]
    runs = run_arms(p, arms, [1, 2, 3, 4, 5], 10)
    assert runs["alone"].picks.shape == (5, 10)
    assert runs["oracle"].picks.mean() < runs["alone"].picks.mean() - 2
    assert (runs["oracle"].hits > runs["alone"].hits).all()
    again = run_arms(p, arms[:1], [1, 2, 3, 4, 5], 10)  # a batch's result does not depend on what else is in it
    assert np.array_equal(again["alone"].picks, runs["alone"].picks)


def _model():
    turns = read_turns(SAMPLE)
    fit = fit_user(turns.observations, "intended")
    return to_user_model(fit, recording=SAMPLE.name, session=turns.config.session,
                         participant=turns.config.participant, observed_source="intended")


def test_user_model_file_round_trips_refuses_others_and_is_never_clobbered(tmp_path):
    model = _model()
    data = encode_user_model(model)
    assert decode_user_model(data) == model
    assert encode_user_model(decode_user_model(data)) == data  # same bytes again
    raw = json.loads(data)
    for change, words in (({"format": "pairplay.policy"}, "not a pairplay user-model file"),
                          ({"version": 99}, "newer than this pairplay"), ({"focus": 3}, "corrupt")):
        with pytest.raises(UserModelFileError, match=words):
            decode_user_model(json.dumps({**raw, **change}).encode())
    path = tmp_path / "m.usermodel.json"
    write_user_model(path, model)
    with pytest.raises(OutputError, match="exists"):
        write_user_model(path, model)
    write_user_model(path, model, force=True)
    assert read_user_model(path) == model
    assert [p.name for p in tmp_path.iterdir()] == ["m.usermodel.json"]  # no temporary file left


def _main(capsys, *args) -> tuple[int, str]:
    """The verb in this process (the same main() as the command; seconds saved per case): (exit, stderr)."""
    capsys.readouterr()
    code = main(["counterfactual", *map(str, args)])
    return code, capsys.readouterr().err


def test_cli_fits_the_sample_and_a_counterfactual_differs_measurably(tmp_path, capsys):
    out = tmp_path / "cf"
    code, err = _main(capsys, SAMPLE, "--policy", "same,oracle", "--seeds", 5, "--out", out)
    assert code == 0, err
    names = sorted(p.name for p in out.iterdir())
    assert names == [".pairplay-counterfactual.manifest", "counterfactual.csv", "counterfactual.md", "counterfactual.png",
                     "sim-helmut-fmt2.usermodel.json"]
    model = read_user_model(out / "sim-helmut-fmt2.usermodel.json")
    assert (model.persona.focus, model.persona.memory) == (4, 4)
    md = (out / "counterfactual.md").read_text()
    oracle_row = next(line for line in md.splitlines() if line.startswith("| oracle |"))
    assert oracle_row.rstrip(" |").endswith("yes")  # the paired 95% interval leaves out 0
    rows = np.genfromtxt(out / "counterfactual.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    same, oracle = (rows["picks"][rows["arm"] == a].mean() for a in ("same", "oracle"))
    recorded = np.mean(read_turns(SAMPLE).picks_per_round)
    assert abs(same - recorded) < 2  # the replayed learner gives what happened
    assert oracle < recorded - 3  # the oracle, against the same fitted user, needs far fewer picks


def _recording(path: Path, *more) -> None:
    """A session's SessionStarted, then `more` events, written by the recorder's writer."""
    cfg = SessionConfig(session="s", participant="sim:deaf", persona="deaf", seed=1, rounds=1)
    w = EventLogWriter(path)
    for i, event in enumerate((ev.SessionStarted(config=cfg),) + more):
        e = stamped(event, session="s", source="game", seq=i + 1, time_ns=10**18 + i)
        w.write(event_key("s", "game", type(event).__name__), encode_event(e), log_time_ns=10**18 + i, sequence=i + 1)
    w.close()


def _no_turn_recording(path: Path) -> None:
    _recording(path)


def test_a_malformed_deal_leaves_its_turn_out_and_says_so(tmp_path):
    path = tmp_path / "odd.mcap"
    faces = [0] * 16 + [1, 2]  # cards 16 and 17 have no partner
    _recording(path, ev.RoundStarted(round=0, faces=faces),
               ev.TurnResolved(round=0, turn=0, first=17, second=0, matched=False, round_over=False),
               ev.TurnResolved(round=0, turn=1, first=0, second=1, matched=True, round_over=False))
    turns = read_turns(path)
    assert len(turns.observations.first) == 1 and "card 17 has no partner" in turns.skipped[0]
    assert np.isfinite(fit_user(turns.observations, "intended").loglik)


def test_cli_mistakes_are_one_line_and_write_nothing(tmp_path, capsys):
    empty, text, no_turn = tmp_path / "empty.mcap", tmp_path / "text.mcap", tmp_path / "noturn.mcap"
    empty.write_bytes(b"")
    text.write_text("not a recording")
    _no_turn_recording(no_turn)
    out = tmp_path / "out"
    cases = [((tmp_path / "missing.mcap",), "no such recording"), ((empty,), "the file is empty"),
             ((text,), "not an MCAP file"), ((tmp_path,), "a folder"),
             ((no_turn,), "no resolved turn"),
             ((SAMPLE, "--policy", "same,best"), "unknown arm 'best'"),
             ((SAMPLE, "--policy", "same,same"), "given twice"),
             ((SAMPLE, "--policy", f"reuse:{tmp_path / 'nope.json'}"), "cannot read"),
             ((SAMPLE, "--policy", f"fixed:{text}"), "not a policy file"),
             ((SAMPLE, "--seeds", "1"), "must be at least 2"),
             ((SAMPLE, "--fit-also", SAMPLE.parent / "sim-ashley-fmt2.mcap"), "fit one participant at a time"),
             ((SAMPLE, "--fit-also", SAMPLE), "given twice"),
             ((SAMPLE, "--fit-also", empty), "the file is empty")]
    for args, words in cases:
        try:
            code, err = _main(capsys, *args, "--out", out)
        except SystemExit as exit_:  # argparse's refusals leave through SystemExit, as in the command
            code, err = exit_.code, capsys.readouterr().err
        assert code == 2, (args, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pairplay counterfactual:") and words in lines[0], (args, lines)
        assert "Traceback" not in err and not out.exists()


def test_cli_never_replaces_an_output_folder_without_force(tmp_path, capsys):
    out = tmp_path / "cf"
    assert _main(capsys, SAMPLE, "--fit-only", "--out", out)[0] == 0
    model = out / "sim-helmut-fmt2.usermodel.json"
    before = model.read_bytes()
    model.write_bytes(b"mine")
    code, err = _main(capsys, SAMPLE, "--fit-only", "--out", out)
    assert code == 2 and "--force" in err and len(err.strip().splitlines()) == 1
    assert model.read_bytes() == b"mine"
    assert _main(capsys, SAMPLE, "--fit-only", "--out", out, "--force")[0] == 0
    assert model.read_bytes() == before  # the same recording, the same bytes
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no temporary folder left


def test_a_forced_fit_only_run_over_a_full_one_leaves_no_stale_comparison(tmp_path, capsys):
    """`--fit-only --force` over a run that played arms kept its counterfactual.csv and .png beside the new
    fit: a comparison of a run that played none looked current. The earlier run's own files the new one
    does not write go; a file that is not the verb's stays."""
    out = tmp_path / "cf"
    assert _main(capsys, SAMPLE, "--policy", "same", "--seeds", 2, "--rounds", 5, "--out", out)[0] == 0
    (out / "notes.txt").write_text("the researcher's")
    assert _main(capsys, SAMPLE, "--fit-only", "--out", out, "--force")[0] == 0
    assert sorted(p.name for p in out.iterdir()) == [".pairplay-counterfactual.manifest", "counterfactual.md", "notes.txt",
                                                     "sim-helmut-fmt2.usermodel.json"]


def test_the_share_of_matched_turns_follows_from_the_picks_of_complete_rounds():
    # an LSPI arm records no trace: its share is hits_of_picks (9 matching turns a round, 2 picks a turn),
    # which must be what the kernel arms' recorded turns give
    from pairplay.core.counterfactual import hits_of_picks, oracle_policy, user_alone
    p = persona("vincent")
    arms = [Arm("q", "q", LearnerConfig()), Arm("alone", "fixed", LearnerConfig(), user_alone()),
            Arm("oracle", "fixed", LearnerConfig(), oracle_policy(p, 0))]
    for name, run in run_arms(p, arms, [7, 8, 9], 6).items():
        assert np.allclose(hits_of_picks(run.picks), run.hits, rtol=0, atol=1e-12), name


def test_the_same_arm_of_an_lspi_recording_replays_lspi_with_its_settings(tmp_path, capsys):
    """`counterfactual` on any LSPI recording was a KeyError traceback: the "same" arm's table of
    algorithms had no "lspi". The arm replays the session's LSPI learner with its recorded settings."""
    from pairplay.core.rng import game_seed
    from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LSPIConfig
    from pairplay.services.session import run_session

    config = SessionConfig(session="cflspi", participant="sim:blind", persona="blind", seed=1, rounds=4,
                           algorithm="lspi", lspi={"improve_every": 3, "tilings": 1}, software_version="test",
                           reward_bonus=DEFAULT_REWARD_BONUS, streams=2)
    path = run_session(config, tmp_path / "cflspi.mcap")
    out = tmp_path / "cf"
    code, err = _main(capsys, path, "--policy", "same,final,q", "--seeds", 3, "--rounds", 12, "--out", out)
    assert code == 0 and "Traceback" not in err, err
    rows = np.genfromtxt(out / "counterfactual.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    same = rows[rows["arm"] == "same"]
    fitted = read_user_model(out / "cflspi.usermodel.json").persona
    seeds = [game_seed(0, "counterfactual:cflspi", i) for i in range(3)]
    rounds = 12
    want = run_games([fitted] * 3, seeds, rounds, mode="lspi", lspi=LSPIConfig(improve_every=3, tilings=1)).picks
    assert np.array_equal(same["picks"].reshape(3, rounds), want)  # LSPI, with the recorded settings
    # the recorded settings tell (the defaults play otherwise on these seeds), and so does the learner
    assert not np.array_equal(want, run_games([fitted] * 3, seeds, rounds, mode="lspi").picks)
    assert not np.array_equal(want, rows["picks"][rows["arm"] == "q"].reshape(3, rounds))


def test_the_share_of_matched_turns_has_an_interval_within_0_and_100_percent():
    """A trial's table said `91.9% [83.7%, 100.2%]`: the t-interval of a mean of shares near 1 passed 100%."""
    from pairplay.core.counterfactual import ArmRuns
    from pairplay.report.counterfactual import Recorded, comparison_rows
    hits = np.array([1.0, 1.0, 0.757])
    rows = comparison_rows(Recorded([20], 0.9, 10), {"same": ArmRuns(np.full((3, 1), 18.0), hits)}, {})
    cell = rows[-1][3]
    assert cell.startswith("91.9% [") and cell.endswith(", 100.0%]"), cell


def test_an_interval_of_picks_per_round_stops_at_18_a_perfect_round():
    """A trial's table said `final 27.33 ± 3.77 [-6.55, 61.22]`: the t-interval of a mean of 2 seeds went below
    18 picks per round (and below 0), which no round can take. The table's interval and the figure's band of
    picks per round are clipped at 18, as the share's is at 0..100%; the paired difference, not a count of
    picks, is not."""
    from pairplay.core.counterfactual import ArmRuns
    from pairplay.report.counterfactual import Recorded, comparison_rows

    final = np.array([[24.0, 25.0], [30.0, 30.66]])  # per seed means 24.5, 30.33: mean 27.4, low < 0
    same = np.array([[18.0, 18.0], [40.0, 40.0]])
    rows = comparison_rows(Recorded([20], 0.9, 10), {"same": ArmRuns(same, np.array([0.5, 0.5])),
                                                     "final": ArmRuns(final, np.array([0.5, 0.5]))}, {})
    for row in rows[2:]:
        low = float(row[2].split("[")[1].split(",")[0])
        assert low == 18.0, row
    assert float(rows[-1][5].split("[")[1].split(",")[0]) < 0  # the paired difference keeps its interval
    from pairplay.report.counterfactual import picks_band

    mean, low, high = picks_band(same)
    assert np.all(low == 18.0) and np.all(high > mean), (low, high)

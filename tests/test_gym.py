"""pairplay.gym: Gymnasium's checks, the study reproduced through the env, the vector env against one env per game."""

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import batch_space

import pairplay.gym  # noqa: F401  (registers the id)
from pairplay.core.geometry import NOT_ONE_CARD_STATE
from pairplay.core.oracle import oracle_policies
from pairplay.core.personas import PERSONAS
from pairplay.core.rng import game_seed
from pairplay.core.simulate import run_games
from pairplay.gym import ENV_ID, MemoryEnv, MemoryVectorEnv


@pytest.mark.parametrize("observation", ["state", "rich"])
def test_gymnasium_check_env_passes_without_a_warning(observation):
    env = gymnasium.make(ENV_ID, persona="deaf", observation=observation, reward_bonus="consistent")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


def _policy():
    oracle, _ = oracle_policies([PERSONAS["wasim"]], 4, 0, 40)
    return oracle[0]


@pytest.mark.parametrize("source,rule", [("intended", "correct"), ("first-pick", "match")])
def test_a_fixed_policy_through_the_env_picks_what_the_study_picks(source, rule):
    policy, wasim, rounds = _policy(), PERSONAS["wasim"], 6
    seed = game_seed(0, "wasim", 3)
    study = run_games([wasim], [seed], rounds, mode="fixed", policy=policy, observed_source=source,
                      reward_bonus=rule, record="all")
    rewards = [float(r) for r in study.trace["reward"]]  # one game: its turns in order
    env = gymnasium.make(ENV_ID, persona="wasim", observed_source=source, reward_bonus=rule)
    picks, got = [], []
    obs, _ = env.reset(seed=seed)
    for _ in range(rounds):
        done = False
        while not done:
            obs, reward, done, truncated, info = env.step(int(policy[obs]))
            got.append(reward)
            assert not truncated
        assert obs == NOT_ONE_CARD_STATE
        picks.append(info["picks"])
        obs, _ = env.reset()
    assert picks == list(study.picks[0]) and got == rewards[:len(got)] and len(got) == len(rewards)


def _same(a, b) -> bool:
    """Two info dicts (or values in them) alike: the same keys, equal arrays, object arrays element by element."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) and a.dtype == object:
        return b.dtype == object and a.shape == b.shape and all(_same(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b) and np.asarray(a).dtype == np.asarray(b).dtype


@pytest.mark.parametrize("observation,source,personas", [("state", "intended", ["blind"] * 6),
                                                         ("rich", "first-pick", ["deaf", "blind", "helmut"] * 2)])
def test_the_vector_env_is_a_sync_vector_env_of_single_envs(observation, source, personas):
    """Gymnasium's SAME_STEP semantics, checked against its SyncVectorEnv of MemoryEnvs: the same observations,
    rewards and ends, the same info layout (a game whose round ended has its step's info in final_info and its
    new round's reset info at the top), and reset() without a seed deals every game's next round (it started
    new games with random seeds; a round's end left its info at the top level)."""
    n, seed = 6, 42
    ours = gymnasium.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", persona=personas,
                              observation=observation, observed_source=source)
    assert isinstance(ours.unwrapped, MemoryVectorEnv)
    assert ours.observation_space == batch_space(ours.single_observation_space, n)
    assert ours.action_space == batch_space(ours.single_action_space, n)
    assert ours.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    sync = SyncVectorEnv([lambda k=k: MemoryEnv(persona=k, observation=observation, observed_source=source)
                          for k in personas], autoreset_mode=AutoresetMode.SAME_STEP)
    a, ia = ours.reset(seed=seed)
    b, ib = sync.reset(seed=seed)
    assert np.array_equal(a, b) and _same(ia, ib) and a in ours.observation_space
    rng = np.random.default_rng(0)
    ended = 0
    for step in range(160):
        if step in (70, 71):  # mid-round, then again at once: every game's next round, as each single env's reset()
            a, ia = ours.reset()
            b, ib = sync.reset()
            assert np.array_equal(a, b) and _same(ia, ib)
        if step == 120:  # a new persona with seeds: new games
            a, ia = ours.reset(seed=[7, 8, 9, 10, 11, 2**64 - 1], options={"persona": "deaf"})
            b, ib = sync.reset(seed=[7, 8, 9, 10, 11, 2**64 - 1], options={"persona": "deaf"})
            assert np.array_equal(a, b) and _same(ia, ib)
        actions = rng.integers(0, 88, n)
        a, ra, ta, ua, ia = ours.step(actions)
        b, rb, tb, ub, ib = sync.step(actions)
        assert np.array_equal(a, b) and np.array_equal(ra, rb) and np.array_equal(ta, tb) and not ua.any()
        assert a in ours.observation_space and ra.dtype == np.float64
        assert _same(ia, ib), (step, ia, ib)
        ended += int(ta.sum())
        if ta.any() and not ta.all():
            assert set(ia) >= {"final_obs", "final_info", "round", "picks"}
    assert ended >= 2 * n  # the games finished rounds before and after the resets
    ours.close()
    sync.close()


def test_the_vector_env_reproduces_the_study_for_many_games():
    policy, n, rounds = _policy(), 40, 3
    personas = [list(PERSONAS)[i % len(PERSONAS)] for i in range(n)]
    seeds = [game_seed(1, k, i) for i, k in enumerate(personas)]
    study = run_games([PERSONAS[k] for k in personas], seeds, rounds, mode="fixed", policy=policy)
    env = MemoryVectorEnv(n, persona=personas)
    obs, _ = env.reset(seed=seeds)
    picks = [[] for _ in range(n)]
    while min(len(p) for p in picks) < rounds:
        obs, _, over, _, info = env.step(policy[obs])
        for g in np.nonzero(over)[0]:
            picks[g].append(int(info["final_info"]["picks"][g]))  # a round's end: its step info is final_info
    assert [p[:rounds] for p in picks] == study.picks.tolist()


def test_bad_options_and_actions_are_refused():
    with pytest.raises(ValueError, match="unknown persona"):
        MemoryEnv(persona="nobody")
    with pytest.raises(ValueError, match="observation"):
        MemoryEnv(observation="pixels")
    env = MemoryEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    env.reset(seed=1)
    with pytest.raises(ValueError, match="composite"):
        env.step(88)
    vec = MemoryVectorEnv(2)
    vec.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="composite"):
        vec.step(np.array([0, 99]))
    obs, info = env.reset(options={"persona": "deaf"})
    assert env.persona.key == "deaf" and obs in env.observation_space


@pytest.mark.parametrize("seed", [2**64, 2**64 + 1, 2**70])
def test_a_seed_beyond_the_rngs_range_is_refused_not_aliased(seed):
    """reset(seed=2**64) played seed 0's games (2**64 + 1 seed 1's): seeds are cut to 64 bits by no one now."""
    with pytest.raises(ValueError, match="0..18446744073709551615"):
        MemoryEnv().reset(seed=seed)
    vec = MemoryVectorEnv(2)
    for seeds in (seed, [3, seed], 2**64 - 1):  # an int seed s gives the games s and s + 1
        with pytest.raises(ValueError, match="0..18446744073709551615"):
            vec.reset(seed=seeds)
    assert MemoryEnv().reset(seed=2**64 - 1)[0] in range(24) and vec.reset(seed=2**64 - 2)[0].shape == (2,)


def test_the_vector_env_refuses_what_the_single_env_refuses():
    """The vector env ignored a mistyped option (it played tatiana), a reset's persona, float actions and
    seeds the single env refuses (-1, 1.7, 2**64 in a list); both now take their input through one check."""
    for make in (lambda **kw: gymnasium.make(ENV_ID, **kw),
                 lambda **kw: gymnasium.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", **kw)):
        with pytest.raises(TypeError, match="persnoa"):
            make(persnoa="deaf")
    env, vec = MemoryEnv(), MemoryVectorEnv(4)
    for bad, error in ((-1, ValueError), (2**64, ValueError), (1.7, TypeError), (2.0, TypeError), ("3", TypeError),
                       (True, TypeError)):
        for reset in (lambda: env.reset(seed=bad), lambda: vec.reset(seed=bad), lambda: vec.reset(seed=[1, bad, 2, 3])):
            with pytest.raises(error, match="seed"):
                reset()
    with pytest.raises(ValueError, match="3 seeds for 4 games"):
        vec.reset(seed=[1, 2, 3])
    env.reset(seed=1)
    vec.reset(seed=1)
    for bad in (3.0, 3.5, "3", None, 88, -1, np.uint64(3), np.array([3]), [3]):
        with pytest.raises(ValueError, match="composite code"):
            env.step(bad)
        with pytest.raises(ValueError, match="composite code"):
            vec.step([0, 1, bad, 2] if np.ndim(bad) == 0 else [bad] * 4)
    with pytest.raises(ValueError, match="composite code"):
        vec.step(np.array([0.5, 1, 2, 3]))
    env.step(np.int64(3))
    vec.step(np.array([0, 1, 2, 3], dtype=np.int32))
    for options, error in (({"personna": "blind"}, ValueError), ({"persona": "zzz"}, ValueError),
                           ({"persona": 5}, TypeError), ({"reset_mask": np.ones(4, bool)}, ValueError)):
        for target in (env, vec):
            with pytest.raises(error, match="persona|reset option"):
                target.reset(seed=2, options=options)
    obs, _ = vec.reset(seed=5, options={"persona": "blind"})
    assert [p.key for p in vec.personas] == ["blind"] * 4
    assert obs.tolist() == [MemoryEnv(persona="blind").reset(seed=5 + i)[0] for i in range(4)]
    assert env.reset(seed=5, options={"persona": "blind"})[0] == obs[0] and env.persona.key == "blind"


def test_gymnasiums_conventions_render_mode_render_and_options_checked_at_construction():
    """render_mode was a TypeError from the constructor, render() a NotImplementedError without a word, and
    observed_source="bogus" was taken by make and refused only at the first reset."""
    makes = (lambda **kw: gymnasium.make(ENV_ID, **kw),
             lambda **kw: gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", **kw))
    for make in makes:
        env = make(render_mode=None)
        assert env.render_mode is None and env.metadata["render_modes"] == []
        env.reset(seed=1)
        with pytest.warns(UserWarning, match="render_mode"):
            assert env.render() is None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Gymnasium's own warning that the mode is not in render_modes
            for mode in ("rgb_array", "human", "ansi"):
                with pytest.raises(ValueError, match=f"render_mode '{mode}' is not supported"):
                    make(render_mode=mode)
        with pytest.raises(ValueError, match="observed source"):
            make(observed_source="bogus")
    with pytest.raises(ValueError, match="None for some games"):
        MemoryVectorEnv(3).reset(seed=[1, None, 2])


def test_info_round_is_the_index_of_the_rounds_deal_from_0():
    """info["round"] counts from 0, as RoundStarted.round and rebuild's curve.csv do (what a person reads counts
    from 1); a round abandoned by reset() counts: the next deal was reported as the same round again."""
    env = MemoryEnv()
    assert env.reset(seed=3)[1] == {"round": 0}
    env.step(0)
    assert env.reset()[1] == {"round": 1}  # round 0's deal abandoned: this is the game's second deal
    done = False
    while not done:
        _, _, done, _, _ = env.step(0)
    assert env.reset()[1] == {"round": 2} and env.reset(seed=3)[1] == {"round": 0}
    vec = MemoryVectorEnv(2)
    vec.reset(seed=3)
    vec.step([0, 0])
    assert vec.reset()[1]["round"].tolist() == [1, 1]


@pytest.mark.parametrize("refused", [{"seed": -1}, {"seed": 1.5}, {"options": {"bogus": 1}},
                                     {"options": {"persona": "nobody"}}])
def test_an_env_whose_first_reset_was_refused_works_and_is_checked_at_the_next(refused):
    """A trial (Gymnasium 1.4): `gymnasium.make`'s env checker marks the first reset checked before it runs,
    so after a refused first reset the next valid one went unchecked and the first step raised a TypeError
    (`cannot unpack non-iterable NoneType object`: its data-reuse check compared against a reset it never
    saw): the env stayed broken. Our checker (gym/env.py EnvChecker) marks a check done only once its call
    succeeded; a refused step alike. The same env then plays like a fresh one."""
    env = gymnasium.make(ENV_ID, persona="deaf")
    with pytest.raises((TypeError, ValueError)):
        env.reset(**refused)
    checker = env.env
    assert type(checker).__name__ == "EnvChecker" and not checker.checked_reset
    obs, info = env.reset(seed=3)
    assert checker.checked_reset and info == {"round": 0}
    with pytest.raises(ValueError):  # an action out of the space: the step's checks wait for a valid one
        env.step(88)
    assert not checker.checked_step
    fresh = gymnasium.make(ENV_ID, persona="deaf")
    assert fresh.reset(seed=3)[0] == obs
    for action in (3, 35, 3, 0):
        assert env.step(action)[:4] == fresh.step(action)[:4]
    # Gymnasium 1.4 added the data-reuse check (and its flag); 1.1-1.3, in the declared range, have none
    assert checker.checked_step and getattr(checker, "checked_data_reuse", True)
    # made again from its spec, it is under this checker alone, not Gymnasium's too
    assert str(gymnasium.make(env.spec)) == str(env) == "<OrderEnforcing<EnvChecker<MemoryEnv<pairplay/Memory-v0>>>>"


BAD_VALUES = ["nobody", "", 5, None, 1.5, b"tatiana", ["tatiana"], {"a": 1}, np.int64(3), np.nan, True, -1,
              2 ** 70, 10 ** 12, np.array([1, 2])]


def test_every_bad_argument_of_either_env_is_a_value_or_type_error():
    """docs/gym.md: a mistake is a ValueError (out of range) or a TypeError (the wrong kind). An unknown
    persona was a KeyError (constructor, persona list, `reset(options={"persona": "nobody"})`) and a huge
    num_envs numpy's OverflowError (2**70) or MemoryError (10**12): every argument of both envs, fed the
    same bad values, raises one of the two kinds or works."""
    def refused_or_taken(call):
        try:
            call()
        except (ValueError, TypeError):
            pass
    for bad in BAD_VALUES:
        for option in ("persona", "reward_bonus", "observation", "observed_source", "render_mode"):
            refused_or_taken(lambda: MemoryEnv(**{option: bad}))
            refused_or_taken(lambda: MemoryVectorEnv(2, **{option: bad}))
        refused_or_taken(lambda: MemoryVectorEnv(2, persona=[bad, "tatiana"]))
        env, vec = MemoryEnv(), MemoryVectorEnv(2)
        for target in (env, vec):
            refused_or_taken(lambda: target.reset(seed=bad))
            refused_or_taken(lambda: target.reset(options=bad))
            refused_or_taken(lambda: target.reset(options={"persona": bad}))
        refused_or_taken(lambda: vec.reset(seed=[bad, 1]))
        env.reset(seed=1), vec.reset(seed=1)
        refused_or_taken(lambda: env.step(bad))
        refused_or_taken(lambda: vec.step([bad, 1]))
    for bad in (2 ** 70, 10 ** 12, 10 ** 7, 0, -1, 1.0, True, "2"):
        with pytest.raises((ValueError, TypeError), match="num_envs"):
            MemoryVectorEnv(bad)
    for target in (MemoryEnv(), MemoryVectorEnv(2)):
        with pytest.raises(ValueError, match="unknown persona 'nobody'; known: ashley"):
            target.reset(options={"persona": "nobody"})

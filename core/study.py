"""The virtual study of thesis 6.2, as pure functions over arrays.

Rule: every persona plays `games` games of `rounds` rounds with online
Q-learning (or online LSPI, `algorithm="lspi"`, core/lspi.py); game g of persona P is seeded by game_seed(seed, P, g), so adding a
persona or a game never changes the others. Each game yields one policy: the
greedy action of its final Q-table, ties broken by a generator seeded from the
game's seed. Evaluation plays every policy with epsilon 0 (a fixed policy) on
games seeded apart from training, beside the two references (user alone,
oracle). Games are independent (core/simulate.py), so independent phases share
one batch: `Evaluations` collects the evaluation games of several experiments
(the comparison, the merged policies, the speed-up's snapshots) and plays them
together, and both arms of the speed-up experiment are one batch.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import DEFAULT_REWARD_BONUS, LearnerConfig, LSPIConfig, Persona

from .learning import greedy_policy
from .oracle import USER_ALONE, oracle_policies
from .rng import game_seed
from .simulate import SimResult, run_games

EVAL_GAME_OFFSET = 1_000_000  # evaluation games are seeded apart from training games
LEARNING_ALGORITHMS = {"q-learning": "q", "lspi": "lspi"}  # the study's learners -> run_games mode
# the speed-up's greedy snapshots: one every 10 rounds, so a speed-up game needs at least 10 rounds
REUSE_SNAPSHOT_EVERY = 10
FIRST_ROUNDS = 50  # the speed-up's measure: online picks per round over the first 50 rounds (thesis 6.4)


class Training(NamedTuple):
    personas: list[Persona]  # one per game, persona-major
    game_index: np.ndarray  # game number within its persona
    seeds: list[int]
    result: SimResult
    greedy: np.ndarray  # (B, 24)


def train(personas: Sequence[Persona], games: int, rounds: int, seed: int,
          config: LearnerConfig = LearnerConfig(), progress=None, reward_bonus: str = DEFAULT_REWARD_BONUS,
          algorithm: str = "q-learning", lspi: LSPIConfig | None = None,
          snapshot_every: int | None = None) -> Training:
    """Train every game with `algorithm` ("q-learning" or "lspi"); the same seeds for either,
    so both learners meet the same deals and users. `snapshot_every` keeps greedy snapshots."""
    if algorithm not in LEARNING_ALGORITHMS:
        raise ValueError(f"algorithm {algorithm!r} is not one of {tuple(LEARNING_ALGORITHMS)}")
    flat = [p for p in personas for _ in range(games)]
    index = np.tile(np.arange(games), len(personas))
    seeds = [game_seed(seed, p.key, int(g)) for p, g in zip(flat, index)]
    result = run_games(flat, seeds, rounds, config, mode=LEARNING_ALGORITHMS[algorithm], progress=progress,
                       reward_bonus=reward_bonus, lspi=lspi, snapshot_every=snapshot_every)
    greedy = np.stack([greedy_policy(q, np.random.default_rng(s)) for q, s in zip(result.q, seeds)])
    return Training(flat, index, seeds, result, greedy)


class Evaluations:
    """Evaluation games of several experiments, played in one batch (epsilon 0, fixed policies).

    `add` returns the slice of rows a request gets; after `play`, `picks[slice]`
    is each row's mean picks per round. Row i of a request plays evaluation
    game `game_index[i]` (default i) of its persona: rows with the same persona
    and index play the very same deals and user draws, whatever else is in the batch.

    Rows that repeat a game are played once: rows with the same persona, game
    index and policy share one game of the most rounds any of them asks for,
    and each reads the sum of its own first rounds (a fixed policy's game does
    not depend on how many rounds follow, and integer picks sum exactly), so a
    row's result is the same whether it plays alone or shares. How to join the
    study's batch: report/future.py.
    """

    def __init__(self, seed: int):
        self.seed = seed
        self._personas: list[Persona] = []
        self._policies: list[np.ndarray] = []
        self._rounds: list[int] = []
        self._index: list[int] = []
        self._planned = None
        self.picks: np.ndarray | None = None

    def add(self, personas: Sequence[Persona], policies: np.ndarray, rounds: int,
            game_index: Sequence[int] | None = None) -> slice:
        if self.picks is not None:
            raise RuntimeError("the batch has been played: queue every request before play()")
        start = len(self._personas)
        policies = np.asarray(policies).reshape(len(personas), -1)
        self._planned = None
        self._personas += list(personas)
        self._policies.append(policies)
        self._rounds += [rounds] * len(personas)
        self._index += [int(i) for i in (range(len(personas)) if game_index is None else game_index)]
        return slice(start, len(self._personas))

    @property
    def total_rounds(self) -> int:
        """Rounds the batch plays (repeated games once)."""
        return int(self._plan()[2].sum())

    def _plan(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(the distinct game each row reads, each game's first row, each game's rounds, every row's policy)."""
        if self._planned is not None:
            return self._planned
        policies = np.concatenate(self._policies) if self._policies else np.zeros((0, 24), dtype=np.int64)
        first: dict = {}
        game_of = np.empty(len(self._personas), dtype=np.int64)
        lead: list[int] = []  # per distinct game: the first row that asked for it
        rounds: list[int] = []
        for i, (p, g, policy) in enumerate(zip(self._personas, self._index, policies)):
            j = first.setdefault((p, g, policy.tobytes()), len(lead))
            if j == len(lead):
                lead.append(i)
                rounds.append(self._rounds[i])
            elif self._rounds[i] > rounds[j]:
                rounds[j] = self._rounds[i]
            game_of[i] = j
        self._planned = game_of, np.array(lead, dtype=np.int64), np.array(rounds, dtype=np.int64), policies
        return self._planned

    def play(self, progress=None) -> np.ndarray:
        game_of, lead, rounds, policies = self._plan()
        personas = [self._personas[i] for i in lead]
        seeds = [game_seed(self.seed, p.key, EVAL_GAME_OFFSET + self._index[i]) for p, i in zip(personas, lead)]
        result = run_games(personas, seeds, rounds, mode="fixed", policy=policies[lead], progress=progress)
        # integer picks: a row's sum over its own rounds is exact, so its mean depends neither on the
        # batch's width nor on a longer row sharing its game
        totals = np.zeros((len(lead), result.picks.shape[1] + 1), dtype=result.picks.dtype)  # < 2**31 picks a game
        np.cumsum(result.picks, axis=1, out=totals[:, 1:])
        del result
        own = np.array(self._rounds, dtype=np.int64)
        self.picks = totals[game_of, own].astype(np.float64) / own
        return self.picks


def evaluate(personas: Sequence[Persona], policies: np.ndarray, rounds: int, seed: int,
             game_index: Sequence[int] | None = None, progress=None) -> np.ndarray:
    """Mean picks per round of each (persona, policy) row, epsilon 0, `rounds` rounds each (see Evaluations)."""
    batch = Evaluations(seed)
    batch.add(personas, policies, rounds, game_index)
    return batch.play(progress)


class Comparison(NamedTuple):
    persona: list[str]
    alone: np.ndarray  # mean picks per round, per persona
    learned: np.ndarray
    learned_spread: np.ndarray  # std over the persona's policies
    oracle: np.ndarray
    oracle_policy: np.ndarray  # (P, 24)
    learned_per_policy: np.ndarray  # (P, games)
    oracle_values: np.ndarray  # (P, 24, 88) expected reward of every action (core/oracle.py)


def compare(personas: Sequence[Persona], training: Training, eval_rounds: int, seed: int,
            oracle_rounds: int = 200, oracle_games: int = 20, progress=None,
            reward_bonus: str = DEFAULT_REWARD_BONUS) -> Comparison:
    """User alone, learned greedy policies and the oracle, per persona, on the same games.

    Each learned policy plays `eval_rounds` rounds; the oracle and the user alone
    play the very same evaluation games beside it (one batch).
    """
    oracle = oracle_policies(personas, oracle_games, seed, oracle_rounds, bonus=reward_bonus)
    batch = Evaluations(seed)
    rows = add_comparison(batch, personas, training, eval_rounds, oracle)
    batch.play(progress)
    return comparison(personas, training, oracle, batch.picks[rows])


def add_comparison(batch: Evaluations, personas: Sequence[Persona], training: Training, eval_rounds: int,
                   oracle: tuple[np.ndarray, np.ndarray]) -> slice:
    """Queue the comparison's games: every learned policy, the oracle and the user alone on the same games."""
    n_p, games = len(personas), len(training.personas) // len(personas)
    owner = np.repeat(np.arange(n_p), games)
    policies = np.concatenate([training.greedy, oracle[0][owner], np.tile(USER_ALONE, (n_p * games, 1))])
    return batch.add(list(training.personas) * 3, policies, eval_rounds, np.tile(training.game_index, 3))


def comparison(personas: Sequence[Persona], training: Training, oracle: tuple[np.ndarray, np.ndarray],
               picks: np.ndarray) -> Comparison:
    """The Comparison from the picks of `add_comparison`'s rows."""
    n_p, games = len(personas), len(training.personas) // len(personas)
    learned, oracle_picks, alone = picks.reshape(3, n_p, games)
    return Comparison([p.key for p in personas], alone.mean(1), learned.mean(1), learned.std(1),
                      oracle_picks.mean(1), oracle[0], learned, oracle[1])


class Speed(NamedTuple):
    """How fast each learner's greedy policy gets within `target` x the oracle (per persona and game)."""

    algorithms: list[str]
    persona: list[str]
    curves: np.ndarray  # (n_alg, P, games, rounds) online picks per round
    snapshot_picks: np.ndarray  # (n_alg, P, games, k) greedy snapshot after every `every` rounds, epsilon 0
    rounds_to_target: np.ndarray  # (n_alg, P, games) first snapshot round within target x oracle; nan if never
    every: int
    target: float


def learning_speed(personas: Sequence[Persona], trainings: dict, oracle_picks: dict, seed: int,
                   snapshot_rounds: int = 20, target: float = 1.10) -> Speed:
    """Compare learners trained with snapshots on the same games (`trainings`: algorithm -> Training).

    Every snapshot plays `snapshot_rounds` rounds with epsilon 0 on evaluation game
    j (the j-th snapshot) of its persona: all learners are judged on the same games.
    """
    names = list(trainings)
    first = trainings[names[0]]
    every = first.result.picks.shape[1] // first.result.snapshots.shape[1]
    snaps = np.stack([trainings[a].result.snapshots for a in names])  # (n_alg, B, k, 24)
    n_alg, n, k = snaps.shape[:3]
    flat = [first.personas[i] for _ in range(n_alg) for i in range(n) for _ in range(k)]
    picks = evaluate(flat, snaps.reshape(-1, snaps.shape[-1]), snapshot_rounds, seed,
                     [j for _ in range(n_alg * n) for j in range(k)]).reshape(n_alg, n, k)
    limit = np.array([oracle_picks[p.key] * target for p in first.personas])
    reached = picks <= limit[None, :, None]
    to_target = np.where(reached.any(-1), (np.argmax(reached, -1) + 1) * every, np.nan)
    P = len(personas)
    games = n // P
    curves = np.stack([trainings[a].result.picks for a in names]).reshape(n_alg, P, games, -1)
    return Speed(names, [p.key for p in personas], curves, picks.reshape(n_alg, P, games, k),
                 to_target.reshape(n_alg, P, games), every, target)


# --- Chapter 6.3-6.4: profiles, merged policies, policy reuse -------------------------------


class UserSet(NamedTuple):
    """Per persona: its profile over all its policies and the one policy that represents it."""

    profiles: dict  # key -> combine.Profile
    users: dict  # key -> combine.User (the policy chosen for combinations)
    updates: dict  # key -> (games, 24) Q updates per state, for explaining incompatibilities
    trained: dict  # key -> combine.Profile over the states every policy updated >= min_updates times, or None


def user_set(personas: Sequence[Persona], training: Training, seed: int, min_updates: int = 50) -> UserSet:
    """Algorithm 3 on each persona's policies; one policy per persona picked at random (thesis 6.2).

    Beside it, the same comparison over the states all of the persona's policies
    trained at least `min_updates` times (thesis 6.4: untrained states explain
    stray incompatibilities).
    """
    from .combine import extract_info, represent, trained_states
    profiles, users, updates, trained = {}, {}, {}, {}
    for p in personas:
        rows = np.array([i for i, q in enumerate(training.personas) if q.key == p.key])
        users[p.key], profiles[p.key] = represent(p.key, training.greedy[rows], training.result.q[rows], seed)
        updates[p.key] = training.result.counts[rows].sum(-1)
        states = trained_states(updates[p.key], min_updates)
        trained[p.key] = extract_info(training.greedy[rows], states) if states.size else None
    return UserSet(profiles, users, updates, trained)


def evaluate_on_personas(personas: Sequence[Persona], policies: dict, games: int, rounds: int,
                         seed: int, progress=None) -> dict:
    """Mean picks per round of every named policy on every persona: {(policy, persona): picks}.

    A policy is (24,) for everyone or a dict persona -> (n, 24) (e.g. each persona's own
    learned policies, played in turn). Every (policy, persona) pair plays the same
    `games` evaluation games of that persona.
    """
    batch = Evaluations(seed)
    pending = add_on_personas(batch, personas, policies, games, rounds)
    batch.play(progress)
    return pending(batch)


def add_on_personas(batch: Evaluations, personas: Sequence[Persona], policies: dict, games: int, rounds: int):
    """Queue `evaluate_on_personas`'s games; returns a function of the played batch giving its dict."""
    rows, table, index, keys = [], [], [], []
    for name, policy in policies.items():
        for p in personas:
            own = policy[p.key] if isinstance(policy, dict) else np.asarray(policy)[None]
            for g in range(games):
                rows.append(p)
                table.append(own[g % len(own)])
                index.append(g)
                keys.append((name, p.key))
    where = batch.add(rows, np.array(table), rounds, index)

    def result(played: Evaluations) -> dict:
        out: dict = {}
        for k, v in zip(keys, played.picks[where]):
            out.setdefault(k, []).append(v)
        return {k: float(np.mean(v)) for k, v in out.items()}
    return result


class ReuseResult(NamedTuple):
    persona: list[str]
    seeds: int
    first50: np.ndarray  # (P, 2, seeds): mean online picks over the first 50 rounds; arm 0 scratch, 1 reuse
    rounds_to_target: np.ndarray  # (P, 2, seeds): first snapshot round within `target` x oracle, nan if never
    curves: np.ndarray  # (P, 2, rounds) online picks per round, mean over seeds
    biases: dict  # held-out key -> combine.Combined of the others


def reuse_experiment(personas: Sequence[Persona], users: UserSet, oracle_picks: dict, seeds: int, rounds: int,
                     seed: int, config: LearnerConfig, snapshot_every: int = REUSE_SNAPSHOT_EVERY, snapshot_rounds: int = 20,
                     target: float = 1.10, progress=None, reward_bonus: str = DEFAULT_REWARD_BONUS) -> ReuseResult:
    """Thesis 6.4 / 7: for each persona held out, Q-learning from scratch vs pi-reuse on the merge of the others."""
    runs = reuse_runs(personas, users, seeds, rounds, seed, config, snapshot_every, progress, reward_bonus)
    batch = Evaluations(seed)
    rows = add_snapshots(batch, runs, snapshot_rounds)
    batch.play()
    return reuse_result(runs, oracle_picks, batch.picks[rows], target)


class ReuseRuns(NamedTuple):
    """Both arms of the speed-up experiment, played as one batch: rows [0, n) scratch, [n, 2n) pi-reuse."""

    personas: list[Persona]  # the held-out personas
    flat: list[Persona]  # one per game of an arm, persona-major
    seeds: int
    snapshot_every: int
    result: SimResult
    biases: dict  # held-out key -> combine.Combined of the others


def reuse_runs(personas: Sequence[Persona], users: UserSet, seeds: int, rounds: int, seed: int,
               config: LearnerConfig, snapshot_every: int = REUSE_SNAPSHOT_EVERY, progress=None,
               reward_bonus: str = DEFAULT_REWARD_BONUS) -> ReuseRuns:
    """Each persona held out: `seeds` games from scratch and the same games with pi-reuse on the merge of the others."""
    from .combine import combine
    biases = {p.key: combine([users.users[q.key] for q in personas if q.key != p.key]) for p in personas}
    flat, seed_list, bias_rows = [], [], []
    for p in personas:
        for s in range(seeds):
            flat.append(p)
            seed_list.append(game_seed(seed, "reuse:" + p.key, s))
            bias_rows.append(biases[p.key].policy)
    bias = np.array(bias_rows)
    n = len(flat)
    result = run_games(flat * 2, seed_list * 2, rounds, config, mode=["q"] * n + ["reuse"] * n,
                       bias=np.concatenate([bias, bias]), progress=progress, snapshot_every=snapshot_every,
                       reward_bonus=reward_bonus)
    return ReuseRuns(list(personas), flat, seeds, snapshot_every, result, biases)


def add_snapshots(batch: Evaluations, runs: ReuseRuns, snapshot_rounds: int = 20) -> slice:
    """Queue the games that say how good each learner's greedy policy was after every `snapshot_every` rounds."""
    snaps = runs.result.snapshots  # (2n, k, 24)
    k = snaps.shape[1]
    n2 = snaps.shape[0]
    return batch.add([runs.flat[i % len(runs.flat)] for i in range(n2) for _ in range(k)],
                     snaps.reshape(-1, snaps.shape[-1]), snapshot_rounds, [j for _ in range(n2) for j in range(k)])


def reuse_result(runs: ReuseRuns, oracle_picks: dict, snap_picks: np.ndarray, target: float = 1.10) -> ReuseResult:
    """The speed-up's tables from the runs and their snapshots' picks (`add_snapshots`' rows)."""
    n, P, seeds = len(runs.flat), len(runs.personas), runs.seeds
    picks = runs.result.picks
    scratch, reuse = picks[:n], picks[n:]
    rounds = picks.shape[1]
    snap_picks = snap_picks.reshape(2, n, -1)
    limit = np.array([oracle_picks[p.key] * target for p in runs.flat])
    reached = snap_picks <= limit[None, :, None]
    first = np.where(reached.any(-1), (np.argmax(reached, -1) + 1) * runs.snapshot_every, np.nan)  # (2, n)
    first50 = np.stack([scratch[:, :FIRST_ROUNDS].mean(1), reuse[:, :FIRST_ROUNDS].mean(1)])  # (2, n)
    curves = np.stack([scratch, reuse]).reshape(2, P, seeds, rounds).mean(2)
    return ReuseResult([p.key for p in runs.personas], seeds,
                       first50.reshape(2, P, seeds).transpose(1, 0, 2),
                       first.reshape(2, P, seeds).transpose(1, 0, 2),
                       curves.transpose(1, 0, 2), runs.biases)


def policy_gaps(cmp: Comparison, training: Training, index: int, top: int = 5) -> list[tuple[int, int, float, int, float, float]]:
    """Where a persona's learned policies lose expected reward against the oracle.

    Per state: (state, the learned policies' most common action, its expected
    reward, the oracle's action, its expected reward, the mean loss over the
    persona's policies), the `top` states with the largest loss.
    """
    key = cmp.persona[index]
    rows = [i for i, p in enumerate(training.personas) if p.key == key]
    values = cmp.oracle_values[index]
    visited = values.any(axis=1)
    out = []
    for s in np.nonzero(visited)[0]:
        chosen = training.greedy[rows, s]
        loss = float(np.mean(values[s].max() - values[s, chosen]))
        modal = int(np.bincount(chosen, minlength=values.shape[1]).argmax())
        best = int(cmp.oracle_policy[index, s])
        out.append((int(s), modal, float(values[s, modal]), best, float(values[s, best]), loss))
    return sorted(out, key=lambda r: -r[-1])[:top]

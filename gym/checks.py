"""What a user hands pairplay.gym, checked once for both environments.

Rule: MemoryEnv and MemoryVectorEnv take their constructor options, personas,
reset seeds, reset options and actions through these functions and no other
check, all at once (a constructor checks every option it is given), so the
vector env refuses exactly what the single env refuses (it had its own, looser
checks: it played tatiana for a mistyped `persnoa=`, ignored
`reset(options={"persona": ...})`, stepped 0.5 as action 0 and took seeds -1
and 1.7). A mistake raises at once and names the value: TypeError for the
wrong kind of value, ValueError for anything else out of range (an unknown
persona too: core's KeyError was the one other kind that got out, against
docs/gym.md; and a num_envs past MAX_NUM_ENVS, which ended in numpy's
OverflowError or MemoryError). The vector env's own additions are only what a
batch adds (one seed or action per game).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium import spaces

from pairplay.arguments import is_integer
from pairplay.core.actions import N_ACTIONS
from pairplay.core.games import check_observed_source
from pairplay.core.personas import persona as find_persona
from pairplay.core.reward import check_bonus_rule
from pairplay.core.rng import check_seed
from pairplay.schemas.config import Persona
from pairplay.numbers import counted

OBSERVATIONS = ("state", "rich")
RENDER_MODES: list[str] = []  # metadata["render_modes"]: the task draws nothing (render_mode None only)
# num_envs at most: a game's arrays take ~0.8 KB (measured: 100,000 games, +80 MB), so a million is ~0.8 GB;
# 10**12 raised MemoryError and 2**70 OverflowError from numpy instead of saying what was asked
MAX_NUM_ENVS = 1_000_000
RESET_OPTIONS = ("persona",)  # what reset(options=...) takes; anything else is a mistake, not ignored


def observation(kind: Any) -> str:
    """The observation kind: "state" (the thesis's Discrete(24)) or "rich" (Box(78))."""
    if kind not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {OBSERVATIONS}, got {kind!r}")
    return kind


def render_mode(mode: Any) -> None:
    """Gymnasium's render_mode: None (nothing is drawn) is the only one; any other is refused here, not
    taken and failed at render()."""
    if mode is not None and mode not in RENDER_MODES:
        raise ValueError(f"render_mode {mode!r} is not supported: pairplay/Memory-v0 draws nothing (its "
                         "metadata render_modes is empty; render_mode None is the one mode; the board is in "
                         "the observation with observation='rich')")


def env_options(reward_bonus: Any, kind: Any, observed_source: Any, mode: Any) -> None:
    """Every constructor option but the persona(s), checked when the env is made, not at its first reset."""
    check_bonus_rule(reward_bonus)
    observation(kind)
    check_observed_source(observed_source)
    render_mode(mode)


def persona(key: Any) -> Persona:
    """A persona of appendix A by key (or full name)."""
    if not isinstance(key, str):
        raise TypeError(f"persona must be a persona's key (a string), got {key!r}")
    try:
        return find_persona(key)
    except KeyError as e:  # core's lookup says KeyError; a bad value here is a ValueError (module rule)
        raise ValueError(e.args[0]) from None


def num_envs(n: Any) -> int:
    """The vector env's number of games: an integer 1..MAX_NUM_ENVS."""
    if not is_integer(n):
        raise TypeError(f"num_envs must be an integer (1..{MAX_NUM_ENVS:,}), got {n!r}")
    if not 1 <= n <= MAX_NUM_ENVS:
        raise ValueError(f"num_envs must be 1..{MAX_NUM_ENVS:,} (a game takes ~0.8 KB), got {n!r}")
    return int(n)


def personas(keys: str | Sequence[str], n: int) -> list[Persona]:
    """One persona per game: one key for all `n`, or a sequence of `n` keys."""
    many = [keys] * n if isinstance(keys, str) else list(keys) if isinstance(keys, (list, tuple)) else None
    if many is None:
        raise TypeError(f"persona must be a key or a list of {counted(n, 'key')}, got {keys!r}")
    if len(many) != n:
        raise ValueError(f"{counted(len(many), 'persona')} for {counted(n, 'game')}")
    return [persona(k) for k in many]


def reset_seed(seed: Any, what: str = "seed") -> int | None:
    """None (a game drawn at random, or the next round) or a game's seed: an integer in core.rng's
    SEED_RANGE (a float, a bool, a negative or a seed past 2**64-1 is refused, never cut or rounded)."""
    return None if seed is None else check_seed(seed, what)


def reset_seeds(seed: Any, n: int) -> list[int] | None:
    """The seeds of `n` games (Gymnasium's vector convention): None (every game None), an int s (game i
    gets s + i) or one seed per game, each as `reset_seed` takes it. A list with None for some games
    and seeds for others is refused: this env starts new games for all or none."""
    if seed is None:
        return None
    if is_integer(seed):
        first = reset_seed(seed)
        return [reset_seed(first + i, f"seed + {i} (game {i}'s seed)") for i in range(n)]
    if not isinstance(seed, (list, tuple, np.ndarray)):
        reset_seed(seed)  # raises: not an integer
    values = list(seed)
    if len(values) != n:
        raise ValueError(f"{counted(len(values), 'seed')} for {counted(n, 'game')}")
    if all(s is None for s in values):
        return None
    if any(s is None for s in values):
        raise ValueError("seed: None for some games and a seed for others; give every game a seed (new games) "
                         "or none (reset() deals every game's next round)")
    return [reset_seed(s, f"seed of game {i}") for i, s in enumerate(values)]


def _bools(value: Any) -> bool:
    """Whether `value` is a bool or holds bools (numpy's too, a list of them: its dtype is bool)."""
    if isinstance(value, (list, tuple)):  # [True, 1] is an int array to numpy
        return any(isinstance(v, (bool, np.bool_)) for v in value) or np.asarray(value).dtype == np.bool_
    return isinstance(value, (bool, np.bool_)) or np.asarray(value).dtype == np.bool_


def reset_options(options: Any) -> Persona | None:
    """The persona a reset switches to (a new game), or None; `options` holds nothing but RESET_OPTIONS."""
    if options is None:
        return None
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict (of {', '.join(RESET_OPTIONS)}), got {options!r}")
    unknown = sorted(str(k) for k in options if k not in RESET_OPTIONS)
    if unknown:
        raise ValueError(f"unknown reset option {unknown[0]!r}; the options are {', '.join(RESET_OPTIONS)} "
                         "(reset_mask too is not one: a reset starts every game over)")
    return persona(options["persona"]) if "persona" in options else None


def _member(space: spaces.Space, value: Any) -> bool:
    """Whether `value` is in `space` (Discrete(88), or its batch: MultiDiscrete), by Gymnasium 1.4's rule
    written out here: an integer (a Python int, or a numpy integer whose dtype casts safely to the space's:
    not uint64) 0..87; a batch an array or sequence of the batch's shape whose dtype casts safely (no float,
    no string, no object). Not `space.contains`: its rule differs over the declared range (1.1-1.2.2 took a
    batch [0, 1, 3.5, 2] and np.uint64(3); 1.1-1.3 raised numpy's OverflowError on 2**70)."""
    if not space.shape:
        if isinstance(value, int):
            return 0 <= value < N_ACTIONS
        return (isinstance(value, (np.generic, np.ndarray)) and value.shape == () and
                np.issubdtype(value.dtype, np.integer) and np.can_cast(value.dtype, space.dtype) and
                0 <= int(value) < N_ACTIONS)
    if isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        value = np.array(value)
    return bool(isinstance(value, np.ndarray) and value.shape == space.shape and
                np.can_cast(value.dtype, space.dtype) and np.all(value >= 0) and np.all(value < N_ACTIONS))


def action(space: spaces.Space, value: Any) -> None:
    """Raises unless `value` belongs to `space`: Discrete(88) for one env, its batch for the vector env
    (one rule for both, `_member`: integers, numpy's too, 0..87; no float, no string, no bool: Gymnasium
    takes True as 1 and a bool array as codes 0 and 1, where reset(seed=True) was refused;
    pairplay/arguments.py: a bool is never an integer)."""
    try:
        ok = _member(space, value) and not _bools(value)
    except (TypeError, ValueError, OverflowError):  # a ragged list, say: numpy cannot make it an array
        ok = False
    if not ok:
        what = (f"action {value!r} is not one of the {N_ACTIONS} composite codes" if not space.shape else
                f"actions must be {counted(space.shape[0], 'composite code')}, one per game, got {value!r}")
        raise ValueError(f"{what} (integers 0..{N_ACTIONS - 1})")

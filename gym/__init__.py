"""pairplay.gym: the robot-assisted Memory task as a Gymnasium environment, for any RL library.

What belongs here: Gymnasium wrappers around `pairplay.core` and nothing else
(no bus, no files): `MemoryEnv` (one game; an episode is one round, a step is
one suggestion) and `MemoryVectorEnv` (many games stepped at once as arrays on
the same core). Importing this package registers the ids below with Gymnasium::

    import gymnasium, pairplay.gym
    env = gymnasium.make("pairplay/Memory-v0", persona="deaf")
    envs = gymnasium.make_vec("pairplay/Memory-v0", num_envs=2048, vectorization_mode="vector_entry_point")
"""

from __future__ import annotations

import gymnasium

from .env import ENV_ID, MemoryEnv
from .vector import MemoryVectorEnv

__all__ = ["ENV_ID", "MemoryEnv", "MemoryVectorEnv"]

if ENV_ID not in gymnasium.registry:
    # the env checker is ours (gym/env.py EnvChecker): Gymnasium's left an env whose first reset was refused
    # broken (its next valid reset unchecked, its first step a TypeError)
    gymnasium.register(id=ENV_ID, entry_point="pairplay.gym.env:checked_env",
                       vector_entry_point="pairplay.gym.vector:MemoryVectorEnv", disable_env_checker=True)

"""The policy file's contract pins the state names core uses (schemas must not import core)."""

from pairplay.core import geometry
from pairplay.schemas import policy


def test_the_policy_files_state_names_are_cores_in_its_order():
    assert policy.STATE_NAMES == geometry.STATE_NAMES and len(policy.STATE_NAMES) == policy.N_STATES

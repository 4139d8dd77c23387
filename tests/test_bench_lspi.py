"""The LSPI and gym bench rows measure what they say (tiny sizes: the figures live in `pairplay bench`)."""

from pairplay.bench import lspi
from pairplay.cli.bench import _ratio


def test_the_lspi_and_gym_measurements_run_on_small_sizes():
    cpu, wall, n = lspi.lspi_per_sample(4, 3)
    assert cpu > 0 and wall > 0 and n > 20
    assert lspi.dense_per_sample(50, 2) > 0 and lspi.dense_solve(40, 1) > 0
    env_rate, core_rate = lspi.env_and_core_rates(16, 1)
    assert env_rate > 0 and core_rate > 0


def test_a_tiny_ratio_is_not_printed_as_zero():
    assert _ratio(0.00012) == "0.00012x" and _ratio(1.987) == "1.99x"

"""The science of pairplay, pure and deterministic.

Everything here is a function of its inputs: numpy arrays in, numpy arrays out
(the inner loops compiled by numba: kernels.py). No I/O, no clock, no global
RNG. Randomness comes in as per-game uniform streams (`pairplay.core.rng`), so
one game gives the same result alone (a live session is a batch of one) or
played in a batch with thousands of others.
"""

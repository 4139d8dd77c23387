"""The science of pairplay, pure and deterministic.

Everything here is a function of its inputs: numpy arrays in, numpy arrays out.
No I/O, no clock, no global RNG. Randomness comes in as per-game uniform streams
(`pairplay.core.rng`), so one game gives the same result alone (a live session
is a batch of one) or stepped together with thousands of others.
"""

"""The MCAP event log: write it, read it, fold it into state, rebuild, recover.

Belongs here: everything that turns recordings into facts without a bus: the
writer the recorder uses, the reader (whole and damaged files), the fold that
every consumer shares (`evolve(state, event)`), rebuild into policy files and
curves, and recover of a file cut short. Does not belong here: anything that
opens a Zenoh session (re-publishing and verification run services, so they
live in `services`).
"""

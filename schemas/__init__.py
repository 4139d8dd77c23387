"""The contract: msgspec Structs for every event, config and file format.

Belongs here: the events and their envelope, the key space of the bus, the
session and learner configs, the policy-file and robot-config formats, and the
JSON Schemas generated from them. Does not belong here: behaviour. A schema
module imports msgspec and the standard library only; everything else in
pairplay imports it, never the other way round.
"""

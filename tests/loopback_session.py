"""A session's services wired to each other in one thread, no Zenoh: fast recordings for verify tests.

Rule: game, learner and simulated participant run in Drivers (services/node.py)
exactly as on the bus; every published event is delivered, in publication
order, to every other Driver (a perfect, order-keeping bus). The result is the
list of events a recorder on that bus would hold, in that order.
"""

from __future__ import annotations

from collections import deque
from itertools import count

from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.node import Driver
from pairplay.services.participant import ParticipantLogic


def loopback_events(config: SessionConfig) -> list:
    clock = count(10**18, 1000).__next__
    drivers = [Driver(LearnerLogic(), config.session, clock), Driver(ParticipantLogic(), config.session, clock),
               Driver(GameLogic(config), config.session, clock)]
    recorded, pending = [], deque(drivers[-1].start())
    while pending:
        e = pending.popleft()
        recorded.append(e)
        key, payload = event_key(e.session, e.source, type(e).__name__), encode_event(e)
        for d in drivers:
            pending.extend(d.receive(key, payload))
    return recorded

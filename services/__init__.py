"""Processes on the Zenoh bus: thin shells around `pairplay.core`.

Belongs here: the shell every service shares (`bus`: sessions and keys;
`node`: the Logic/Driver contract; `runner`: the thread that feeds a Logic
from the bus), then one module or folder per service: `game`, `learner`,
`participant` (the simulated user), `recorder`, `combiner`, `replayer`
(re-publishes a recording), `robot/` (the robot bridge), `view/` (the rerun
view), and `verify` (fresh services against a recording's inputs).
Does not belong here: decisions (they are in `core`), argument parsing and
printing (`cli`), benchmarks (`bench`), report writing (`report`).
Only this package (and `bench`, which measures it) imports zenoh, the robot
clients, the web server or rerun.
"""

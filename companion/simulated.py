"""The simulator plugged into the application: the simulated camera as a configured frame
source. The frame sources (:mod:`companion.sources`) never import the simulator; a command
that offers scenarios hands :func:`open_sim` to :func:`companion.sources.factory.open_source`
(docs/architecture.md, "Packages and the direction of imports")."""

from __future__ import annotations

import dataclasses

from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sim.source import SimCameraSource
from companion.sources.base import FrameSource
from companion.sources.config import SourceConfig


def open_sim(c: SourceConfig) -> FrameSource:
    """The simulated camera for a scenario name or file (``c.spec``), with ``c.seed`` if
    set."""
    scenario = load_scenario(c.spec)
    if c.seed:
        scenario = dataclasses.replace(scenario, seed=c.seed)
    return SimCameraSource(Simulator(scenario), realtime=c.realtime, loop=c.loop)

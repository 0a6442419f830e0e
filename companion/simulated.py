"""The simulator plugged into the application: the simulated cameras as frame sources.

Neither the frame sources (:mod:`companion.sources`) nor ``companion run`` import the
simulator.  :func:`register` plugs its two source kinds into
:func:`companion.sources.factory.open_source` -- ``sim`` (a scripted scenario) and ``follow``
(the scenario's world seen from the pose an autopilot simulator reports); the command line
names this module as their provider (``companion.cli.PLUGINS``), and the factory imports it
and calls :func:`register` when such a source is first opened (docs/architecture.md,
"Packages and the direction of imports").  What a flight needs of them beyond frames (their truth,
their landmarks' textures, their camera) they say through the protocols of
:mod:`companion.sources.base`.
"""

from __future__ import annotations

import dataclasses

from companion.errors import ConfigError, InputError
from companion.follow import FollowCameraSource, TelemetryFeed, command_sender, follow_simulator
from companion.sim.scenario import load_scenario
from companion.sim.simulator import Simulator
from companion.sim.source import SimCameraSource
from companion.sources.base import FrameSource
from companion.sources.config import SourceConfig
from companion.sources.factory import OpenContext, plug_in


def open_sim(c: SourceConfig, _context: OpenContext | None = None) -> FrameSource:
    """The simulated camera for a scenario name or file (``c.spec``), with ``c.seed`` if
    set."""
    scenario = load_scenario(c.spec)
    if c.seed:
        scenario = dataclasses.replace(scenario, seed=c.seed)
    return SimCameraSource(Simulator(scenario), realtime=c.realtime, loop=c.loop)


def open_follow(c: SourceConfig, context: OpenContext) -> FrameSource:
    """``source.kind = "follow"``: the scenario's world with the flight's landmark map about
    the EKF origin, seen from the pose the autopilot simulator reports (docs/sitl.md)."""
    if context.link is None or context.origin is None:
        raise InputError("source.kind = \"follow\": the camera follows an autopilot "
                         "simulator's truth, so it needs the MAVLink link: use `companion run` "
                         "(docs/sitl.md)")
    if not context.map_path:
        raise ConfigError("source.kind = \"follow\": the simulated camera renders the landmarks "
                          "of landmarks.map_path: set it to the map the autopilot simulator's "
                          "world uses (docs/sitl.md)")
    link: TelemetryFeed = context.link  # type: ignore[assignment]
    sim = follow_simulator(load_scenario(c.spec), context.map_path, context.origin)
    return FollowCameraSource(sim, link, context.origin, context.profile, c.follow,
                              request=command_sender(link))


def register() -> None:
    """Plug the simulated cameras into the frame-source factory (idempotent)."""
    plug_in("sim", open_sim)
    plug_in("follow", open_follow)

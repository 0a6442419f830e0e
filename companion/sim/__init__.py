"""The simulated world: landmarks, a scripted drone trajectory, a camera renderer, effects.

The trajectory and the world are the shared truth: the simulated camera renders what the
drone sees, and the fake autopilot (``mavlink_bridge``) is handed
:meth:`~companion.sim.trajectory.Trajectory.state_at` to report the same motion.

A leaf: it imports of the application only :mod:`companion.core` (frames, truth rows, the
landmark record and map file, configuration building) and :mod:`companion.errors`; the
application's adapters around it are ``companion/simulated.py``, ``companion/follow.py`` and
``companion/calibration_boards.py`` (docs/architecture.md).
"""

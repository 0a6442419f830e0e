"""The simulated world: landmarks, a scripted drone trajectory, a camera renderer, effects.

The trajectory and the world are the shared truth: the simulated camera renders what the
drone sees, and the fake autopilot (``mavlink_bridge``) is handed
:meth:`~companion.sim.trajectory.Trajectory.state_at` to report the same motion.
"""

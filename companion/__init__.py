"""landmark-companion: track known landmarks, send vision fixes to ArduPilot or PX4.

Importing the package changes nothing in the process's environment: the ``companion``
entry point (:mod:`companion.launch`) limits the native thread pools.
"""

__version__ = "0.1.0"

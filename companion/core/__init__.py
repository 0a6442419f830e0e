"""The records and file formats the simulator and the application share: frames, the
recorded-stream format and its truth rows, the landmark record, its table rows and the map
file, configuration building from field metadata, and where the shipped configuration is.

Imports only :mod:`companion.errors` of the application, so that ``companion.sim`` can stay a
leaf (docs/architecture.md; tests/test_import_layers.py).
"""

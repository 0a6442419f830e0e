"""Code the tests, the scenario tests and the benchmarks share (never the shipped package,
which imports none of it): a throwaway PostGIS cluster (``pgcluster``), rendered
calibration sessions (``boards``), a ``companion run`` configuration for a simulated flight
(``flightconfig``) and the soak (``soak``). Importable from the repository's root (pytest's
rootdir, ``PYTHONPATH=.`` for a benchmark); docs/architecture.md, "Packages and the
direction of imports"."""

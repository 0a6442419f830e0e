"""The shipped configuration of landmark-companion, installed as the package
``companion_config`` (pyproject.toml maps it to this folder) and read through
``importlib.resources`` by :func:`companion.settings.config_dir`.  No code lives here."""

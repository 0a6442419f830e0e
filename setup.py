"""The package list, which pyproject.toml cannot express: the code's packages found in the
repository's root plus ``companion_config``, the shipped configuration that stays in
``config/`` (mapped in pyproject.toml's ``[tool.setuptools.package-dir]``)."""

from setuptools import find_packages, setup

setup(packages=[*find_packages(include=["companion*", "tracker*", "mavlink_bridge*",
                                                 "fieldbounds*"]),
                "companion_config"])

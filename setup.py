"""The package list, which pyproject.toml cannot say: the repository's configs/ folder installs as the package
data ``quad_uneven_env.configs`` (read through importlib.resources when the package is not a source checkout)."""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["quad_uneven_env*", "planners*", "agents*"]), "quad_uneven_env.configs"],
    package_dir={"quad_uneven_env.configs": "configs"},
)

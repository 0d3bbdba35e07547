"""Package layout only (metadata is in pyproject.toml): the repository's `render/` and `bench/`
folders install under orthosim's own names, `orthosim_render` and `orthosim_bench`, so nothing
generic lands at the top of site-packages; the shipped case files of `cases/` install inside the
package as `orthosim/cases/` (package data), so an installed orthosim has its demo and bench case."""

from setuptools import find_packages, setup

PACKAGE_DIRS = {"orthosim_render": "render", "orthosim_bench": "bench"}
DATA_DIRS = {"orthosim.cases": "cases"}  # folders of data files only (no Python): see package-data

packages = find_packages(include=["orthosim", "orthosim.*"])
package_dir = {}
for name, folder in PACKAGE_DIRS.items():
    packages.append(name)
    package_dir[name] = folder
    packages += [f"{name}.{sub}" for sub in find_packages(where=folder)]
for name, folder in DATA_DIRS.items():
    packages.append(name)
    package_dir[name] = folder

setup(packages=packages, package_dir=package_dir)

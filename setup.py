"""Package layout only (metadata is in pyproject.toml): the repository's `render/` and `bench/`
folders install under orthosim's own names, `orthosim_render` and `orthosim_bench`, so nothing
generic lands at the top of site-packages."""

from setuptools import find_packages, setup

PACKAGE_DIRS = {"orthosim_render": "render", "orthosim_bench": "bench"}

packages = find_packages(include=["orthosim", "orthosim.*"])
package_dir = {}
for name, folder in PACKAGE_DIRS.items():
    packages.append(name)
    package_dir[name] = folder
    packages += [f"{name}.{sub}" for sub in find_packages(where=folder)]

setup(packages=packages, package_dir=package_dir)

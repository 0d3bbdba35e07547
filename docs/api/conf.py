"""Sphinx configuration of orthosim's API reference, built from the public names' docstrings:
`sphinx-build -W docs/api out/api` (the suite builds it with warnings as errors)."""

project = "orthosim"
author = "orthosim developers"
extensions = ["sphinx.ext.autodoc"]
autodoc_typehints = "description"  # types beside each parameter, not in a long signature
autodoc_member_order = "bysource"
autodoc_default_options = {"members": False}
html_theme = "alabaster"
exclude_patterns = ["_build"]

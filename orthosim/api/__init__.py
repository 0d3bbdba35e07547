"""The library's face: what `import orthosim` offers a script or a notebook, in a few calls.

`simulation` (`build` a case's model, `simulate` it step by step in memory, ask its `contacts` at any
poses) and `staging` (`stage` a case's set-up into aligners, check the plan in memory, write its
files). `orthosim/__init__.py` loads these names lazily, so `import orthosim` stays light.
"""

"""Aligner staging: split a planned set-up into stages within per-stage limits, each stage's motion
free of contact between any two teeth.

Modules: `target` (the case's `[start]` and `[target]` sections, movements in the tooth's own
terms, target meshes registered to the start), `limits` (per-stage limits), `contacts` (the exact
check of one stage's motion, asked through `orthosim.collision`'s contract), `ipr` (interproximal reduction where teeth do not fit at the
target), `plan` (the planner), `chart` (stages.json, staging.csv, ipr.csv), `commands`
(`orthosim stage`, the core half; the drawing is `orthosim_render.staging`), `bench` (planning time).
"""

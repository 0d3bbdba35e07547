"""Aligner staging: split a planned set-up into stages within per-stage limits, each stage's motion
free of contact between any two teeth.

Modules: `caseplan` (a case read and planned, without drawing: what `orthosim stage` and scripts
call), `limits` (per-stage limits), `contacts` (the exact check of one stage's motion, asked through
`orthosim.collision`'s contract), `sweep` (a pair's motion over a stage, for the certificate), `ipr`
(interproximal reduction where teeth do not fit at the target), `reduction` (the reduction as a
plane cut of each contact side, the teeth every later stage holds), `plan` (the planner),
`certificate` (what the plan guarantees, proven), `verify` (a written staging re-checked from its
files), `certcheck` (certificate.json's figures held to their recomputation), `modelcheck` (the
stage models held to stages.json), `stagesfile` (stages.json read back), `chart` (stages.json,
staging.csv, ipr.csv), `models` (each stage's arches for the lab). The set-up itself is read by `orthosim.exchange.target`; the drawing is
`orthosim_render.staging`.
"""

"""Measurement of orthosim from outside the product: `orthosim bench` and the studies behind it.

Installed as `orthosim_bench`. Nothing in `orthosim/` (but the CLI, the composition root) or in
`render/` imports it; each module takes what it measures as arguments.
`render` (stage and end-to-end throughput, the bench record), `summary` (the lines `orthosim bench`
prints), `collision` (detector timings), `spheretree` (tree build), `batch` (animations per minute),
`staging` (staging time), `report` (report time), `memory` (peak memory of long runs), `startup`
(launch to first step), `backends` (render frames/s through each offscreen OpenGL backend found),
`closure` (the bite's closure against the rest of the step), `labels` (the label pass of semantic
goldens), `rootaccuracy` (estimated roots against real ones), `mechanics` (the ligament's
times and the tables of docs/notes/tooth-mechanics.md), `scanarch` (a synthetic labelled arch
scan made ready, cold and warm), `subruns` (a failed or refused sub-run: its figure null, a line
naming it, the bench's exit status 1), `viewer` (the 3D page's bytes, load time and frame time in Chromium).
"""

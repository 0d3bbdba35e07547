"""Measurements of a posed dentition or a finished run, read by reports and users.

`occlusion` (overjet, overbite, molar relation, Bolton), `occlusalcontacts` (where the arches
meet, per facing pair), `distancemap` (every crown vertex's distance to the opposing arch),
`contacttable` (which teeth touched during a run), `spaceanalysis` (space available against space
needed), `metrics` (figures users compare across cases and detectors).
"""

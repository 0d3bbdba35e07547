"""Measurements of a posed dentition or a finished run, read by reports and users.

`occlusalcontacts` (where the arches meet, per facing pair), `distancemap` (every crown vertex's
distance to the opposing arch), `contacttable` (which teeth touched during a run), `spaceanalysis`
(space available against space needed), `metrics` (figures users compare across cases and
detectors). The occlusal measures themselves (overjet, overbite, molar relation, Bolton) are the
model's: `orthosim.model.occlusion`.
"""

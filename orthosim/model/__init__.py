"""The dental model: what a patient's teeth are, before anything moves them.

`fdi` (tooth numbering), `anatomy` (average tooth dimensions), `toothshape` (parametric tooth
meshes), `archform` (arch curves), `tooth` (one tooth's mesh, frame and landmarks), `dentition` (a
patient's teeth), `parametric` (the parametric dentition in normal occlusion), `rootsynthesis`
(roots estimated under scanned crowns), `occlusion` (overjet, overbite, molar relation, Bolton),
`dentition_cache` (built dentitions kept on disk).
"""

"""Tooth mechanics: how a tooth answers a force system, before any step is taken.

`resistance` (centre of resistance rules), `ratelaw` (the rate law's parameter sets: the paper's and
the clinical fit), `biomechanics` (a tooth's loads -> its motion: force system, wire, rate law),
`ligament` (a tooth held by its periodontal ligament: the root's 6x6 stiffness, centre of
resistance, axes of resistance, the motion and centre of rotation of any force system),
`ligamentmotion` (a step's motion from the ligament's compliance and the rate law), `vec`
(small vector helpers). The step that applies these (`orthosim.movement`) sits above; the
case reader (`orthosim.exchange.case`) validates its settings against these names.
"""

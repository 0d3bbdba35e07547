"""The names of the collision detectors, in the paper's order, then the exact mesh reference.

The one list: the case format, the command line, the simulator and the collision package read it
from here (a module with no imports, so that parsing a case or building the CLI pulls in nothing).
"""

DETECTORS = ("circles", "discrete", "continuous", "exact")
PAPER_DETECTORS = DETECTORS[:3]  # the paper's three (a report's default), without the exact reference

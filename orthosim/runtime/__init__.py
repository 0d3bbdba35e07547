"""The run's plumbing: phases of a run, its output folder, child processes and how they end.

`run` (one case run in phases), `outputfolder` (private folder swapped in whole), `runfolder`
(what a finished run leaves and how readers tell it), `background` (the simulation in a child
process beside the renderer), `lifeline` (helpers die with their parent).
"""

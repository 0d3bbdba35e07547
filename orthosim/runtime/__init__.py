"""The run's plumbing: phases of a run, its output folder, child processes.

`options` (what a user asks of a run and of its drawing: `RunOptions`, `RenderOptions`), `run`
(one case run in phases), `stream` (the simulation's record stream and what it writes as it
goes), `strategies` (where the simulation runs: in process, a forked or a spawned child),
`outputfolder` (private folder swapped in whole), `runfolder` (what a finished run leaves and how
readers tell it), `background` (the simulation in a child process beside the renderer). How helper
processes end with their parent is `orthosim.system.lifeline`.
"""

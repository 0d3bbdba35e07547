"""The `orthosim` command line: the one composition root, wiring the core to the renderer
(`orthosim_render`) and to the measurement package (`orthosim_bench`).

One module per command or family of commands, each a thin layer over the library: `run` (`run`,
`demo`), `check`, `occlusion`, `stage` (`stage`, `stage verify`), `imgdiff`, `report`, `bench`,
`batch`, `spheretree`, `collide`, `evidence`, `cases`; `options` holds the options several share,
`app` the group and the console entry. No other package imports click or defines a command.
Commands import the renderer lazily inside their bodies, so `orthosim --help` and the
simulation-only commands never load OpenGL. Every error a user can cause is an `OrthosimError`;
`entry` prints it as one line on stderr and exits with its code (2), never with a traceback.
"""

from orthosim.cli.app import entry, main

__all__ = ["entry", "main"]

"""Everything that draws or writes images, video and reports for orthosim.

Importing any module of this package selects OSMesa as PyOpenGL's platform (unless the user set
PYOPENGL_PLATFORM), because PyOpenGL fixes its platform at its own first import: doing it here
means no import order of ours or of a test can end up with a GLX platform on a headless machine.
"""

import os as _os

_os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

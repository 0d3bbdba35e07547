"""Everything that draws or writes images, video and reports for orthosim (installed as `orthosim_render`).

Importing this package changes nothing in the process: the OpenGL backend (EGL or OSMesa) is chosen
when something first draws, in `orthosim_render.glbackend`, and only then is PYOPENGL_PLATFORM set.
"""

"""orthosim: headless orthodontic treatment simulator (core; never imports OpenGL)."""

__version__ = "0.1.0"

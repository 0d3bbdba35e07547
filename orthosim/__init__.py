"""orthosim: headless orthodontic treatment simulator (the core; it never imports OpenGL).

Packages, bottom layer first (each imports only those above it in this list; DEVELOPERS.md holds
the order): `errors` (every error a user can cause), `storage` and `system` (bytes on disk, the
process), `geometry`, `model` (teeth and dentitions), `spheretree` and `mechanics`, `collision`,
`analysis`, `exchange` (files in and out), `movement` (the step), `evidence` and `staging`,
`runtime` (a run), `batch`, and `cli` (the command line, the one composition root).
"""

__version__ = "0.1.0"

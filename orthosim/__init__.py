"""orthosim: headless orthodontic treatment simulator (the core; it never imports OpenGL).

The library in a few calls (loaded on first use, so `import orthosim` stays light)::

    import orthosim
    case = orthosim.load_case("cases/case1_first_premolar_extraction.toml")  # Case; OrthosimError on bad input
    model = orthosim.build(case)                      # MovementModel: teeth, sphere trees, mechanics (cached)
    for record in orthosim.simulate(model, steps=5):  # StepRecord: time_days, poses {fdi: (4, 4) mm}, touching
        found = orthosim.contacts(model, record.poses)
    staging = orthosim.stage(orthosim.load_case("cases/staging_lower_incisor_crowding.toml"))
    staging.verify().holds                            # staging.write(folder) writes its files

Drawing a step is `orthosim_render.render_frame(model, record)`. Every error a user can cause is an
`OrthosimError`.

Packages, bottom layer first (each imports only those above it in this list; DEVELOPERS.md holds
the order): `errors` (every error a user can cause), `storage` and `system` (bytes on disk, the
process), `geometry`, `model` (teeth and dentitions), `spheretree` and `mechanics`, `collision`,
`analysis`, `exchange` (files in and out), `movement` (the step), `evidence` and `staging`,
`runtime` (a run), `batch` and `api` (the library's face), and `cli` (the command line, the one
composition root).
"""

from orthosim.system.lazy import lazy_names

__version__ = "0.1.0"

# the public names and the modules that define them, imported on first use (PEP 562)
_FROM = {
    "load_case": "orthosim.exchange.case", "Case": "orthosim.exchange.case",
    "build": "orthosim.api.simulation", "simulate": "orthosim.api.simulation", "contacts": "orthosim.api.simulation",
    "stage": "orthosim.api.staging", "Staging": "orthosim.api.staging",
    "MovementModel": "orthosim.movement.model", "StepRecord": "orthosim.movement.records",
    "Dentition": "orthosim.model.dentition", "Tooth": "orthosim.model.tooth",
    "SphereTree": "orthosim.spheretree.tree", "Contacts": "orthosim.collision.contract",
    "StageLimits": "orthosim.staging.limits",
    "OrthosimError": "orthosim.errors",
}
__all__ = ["__version__", *sorted(_FROM)]
__getattr__ = lazy_names(__name__, _FROM)


def __dir__() -> list[str]:
    return sorted({*globals(), *_FROM})

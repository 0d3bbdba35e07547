"""`orthosim collide ...`: the collision detectors' accuracy report, timings and a one-step query.

`collide bench` measures through `orthosim_bench.collision` (measurement lives outside the product).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from orthosim.exchange.shareddata import open_full_jaw_dir
from orthosim.collision.contract import CollisionError, CollisionRequest
from orthosim.collision.detectors import DETECTORS



@click.group()
def collide() -> None:
    """Collision detection: accuracy studies against the exact mesh test, timings, one query."""


@collide.command()
@click.option("--out", "out_file", type=click.Path(path_type=Path), default=Path("out/collision_validation.json"),
              show_default=True, help="JSON report to write.")
@click.option("--poses", type=click.IntRange(1), default=10000, show_default=True,
              help="Random near-contact poses for the discrete study (split across tooth sets).")
@click.option("--motions", type=click.IntRange(1), default=2000, show_default=True,
              help="Random motions over one step for the continuous study (split across tooth sets).")
@click.option("--samples", type=click.IntRange(10), default=400, show_default=True,
              help="Exact collision tests per step for the continuous ground truth.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--real-folder", type=click.Path(path_type=Path), default=open_full_jaw_dir("maxilla"), show_default="../shared/data/open-full-jaw-patient26/maxilla beside the repository, or $ORTHOSIM_SHARED_DATA/...",
              help="Open-Full-Jaw maxilla folder; its teeth are studied when it exists.")
@click.option("--trees", type=click.Choice(["fit", "octree"]), default="fit", show_default=True,
              help="Sphere-tree builder method (trees are cached on disk).")
def validate(out_file: Path, poses: int, motions: int, samples: int, seed: int, real_folder: Path, trees: str) -> None:
    """Sphere-tree detectors vs the exact mesh test: misses, false-positive rates, contact times."""
    from orthosim.spheretree.build import DEPTH, default_branching
    from orthosim.spheretree.cache import cached_sphere_tree
    from orthosim.collision.validate import run_validation

    if not real_folder.is_dir():
        click.echo(f"orthosim: warning: no real teeth at {real_folder}; the study covers the parametric and "
                   "thin-root sets only (pass --real-folder or set ORTHOSIM_SHARED_DATA)", err=True)
    report = run_validation(out_file, n_poses=poses, n_motions=motions, seed=seed, real_folder=real_folder,
                            samples=samples, tree_builder=lambda mesh: cached_sphere_tree(mesh, method=trees),
                            tree_label=f"orthosim.spheretree cached_sphere_tree(method={trees!r}, "
                                       f"{default_branching(trees)} x {DEPTH} levels)")
    click.echo(json.dumps(_headline(report), indent=1))
    click.echo(f"report written to {out_file}")


def _headline(report: dict) -> dict:
    out = {}
    for name, res in report["discrete"]["sets"].items():
        far = report["discrete_far"]["sets"][name]["false_positive_rate"]
        out[f"discrete/{name}"] = {"poses": res["poses"], "false_negatives": res["false_negatives"],
                                  "fp_rate": {**{k: v["rate"] for k, v in res["false_positive_rate"].items()},
                                              "far_>0.5mm": far[">0.5mm"]["rate"]},
                                  "fp_rate_by_band": {k: v["rate"] for k, v in res["false_positive_rate_by_band"].items()}}
    for name, res in report["continuous"]["sets"].items():
        a = res["by_kind"]["all"]
        out[f"continuous/{name}"] = {k: a[k] for k in ("motions", "exact_contacts", "missed_by_sphere_trees",
                                                      "later_than_exact_refined", "refined_within_tolerance")}
    return out


@collide.command()
@click.argument("case", required=False, type=click.Path(path_type=Path))
@click.option("--step", "step_number", type=click.IntRange(0), default=0, show_default=True,
              help="With CASE: the simulation step to query (0: the initial state).")
@click.option("--detector", type=click.Choice(DETECTORS), default="discrete", show_default=True)
@click.option("--resolution", type=click.Choice(["coarse", "smooth"]), default="coarse", show_default=True,
              help="Without CASE: the parametric model's resolution.")
@click.option("--trees", type=click.Choice(["fit", "octree"]), default="fit", show_default=True,
              help="Sphere-tree builder method (trees are cached on disk).")
def step(case: Path | None, step_number: int, detector: str, resolution: str, trees: str) -> None:
    """One whole-arch query: the case's teeth at a simulation step (default: the parametric model at rest)."""
    from orthosim.spheretree.cache import cached_sphere_tree
    from orthosim.collision.detect import detect_step
    from orthosim.collision.model import CollisionModel

    builder = lambda mesh: cached_sphere_tree(mesh, method=trees)  # noqa: E731
    if case is None:
        from orthosim.model.parametric import parametric_dentition

        d = parametric_dentition(resolution=resolution)
        model = CollisionModel.from_dentition(d, tree_builder=builder)
        start = end = d.rest_poses()
        pairs = None
        where = {"model": d.description}
    else:
        from orthosim.exchange.case import load_case
        from orthosim.movement.simulation import MovementModel, simulate

        c = load_case(case)
        if step_number > c.steps:
            raise CollisionError(case, "--step", f"{step_number} is past the case's last step ({c.steps})",
                                 f"give a step from 0 to {c.steps}")
        movement = MovementModel.build(c, tree_builder=builder if trees != "fit" else None)
        model = movement.collision
        previous = record = None
        for record in simulate(movement, c.detector, steps=step_number):  # the case's own detector moves the teeth
            previous = previous if record.step == step_number else record
        start = (previous or record).poses  # continuous: the motion into the step; others: its end poses
        end = record.poses
        pairs = list(movement.pairs)
        where = {"case": c.name, "step": step_number, "time_days": record.time_days,
                 "moving": sorted(record.moving)}
    res = detect_step(model, start, end, pairs=pairs, detector=detector, request=CollisionRequest())
    click.echo(json.dumps({**where, "detector": detector, "candidate_pairs": len(res.pairs),
                           "touching": [list(p) for p in res.touching_pairs()],
                           "leaf_pairs": int(len(res.leaf_pairs)), "first_time_of_contact": res.first_time_of_contact}))


@collide.command("bench")
@click.option("--out", "out_file", type=click.Path(path_type=Path), default=None, help="Also write the JSON here.")
@click.option("--resolution", type=click.Choice(["coarse", "smooth"]), default="smooth", show_default=True,
              help="Parametric model resolution.")
@click.option("--repeats", type=click.IntRange(1), default=50, show_default=True)
@click.option("--trees", type=click.Choice(["fit", "octree"]), default="fit", show_default=True,
              help="Sphere-tree builder method (trees are cached on disk).")
@click.option("--keep-freed-memory", is_flag=True, help="Tune glibc to keep freed memory (see orthosim.system.malloc).")
def bench(out_file: Path | None, resolution: str, repeats: int, trees: str, keep_freed_memory: bool) -> None:
    """Microseconds per whole-arch step of every detector and of python-fcl, same pairs, one run."""
    if keep_freed_memory:
        from orthosim.system.malloc import keep_freed_memory as keep

        keep()
    from orthosim.model.parametric import parametric_dentition
    from orthosim.spheretree.build import DEPTH, default_branching
    from orthosim.spheretree.cache import cached_sphere_tree
    from orthosim_bench.collision import collision_timings

    res = collision_timings(parametric_dentition(resolution=resolution), repeats=repeats,
                            tree_builder=lambda mesh: cached_sphere_tree(mesh, method=trees))
    res["model"] = f"parametric {resolution}, {trees} sphere trees ({default_branching(trees)} x {DEPTH} levels)"
    res["keep_freed_memory"] = keep_freed_memory
    text = json.dumps(res, indent=1)
    click.echo(text)
    if out_file is not None:
        from orthosim.storage.atomic import write_text

        write_text(out_file, text)

"""The one contract every detector honours: a request says what is wanted, a result says what was found.

Modelled on FCL's CollisionRequest / CollisionResult. The simulator and the renderer read a
`StepResult` and never need to know which detector produced it: bounding circles, discrete sphere
trees, continuous sphere trees or the exact mesh test all fill the same fields. The leaf arrays hold what is drawn as
contact: overlapping leaf spheres for the sphere-tree detectors; for circles, which has no leaves,
one sphere per touching pair marking the lens where its circles overlap (leaf index -1,
`circles.overlap_spheres`); the exact test leaves them empty.

Units: millimetres for positions and radii, arch frame for world-space arrays; time is the
fraction of the step in [0, 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from orthosim.errors import OrthosimError


class CollisionError(OrthosimError):
    """A collision query asks for something the model cannot answer (unknown detector, missing pose)."""


# what a refined time of first contact means (`CollisionRequest.contact`)
WITHIN_TOLERANCE = "within_tolerance"
INTERSECTING = "intersecting"
CONTACTS = (WITHIN_TOLERANCE, INTERSECTING)


@dataclass(frozen=True)
class CollisionRequest:
    """What a caller wants from one whole-arch query.

    all_leaf_pairs: True collects every overlapping leaf pair (what the renderer highlights);
        False stops each tooth pair at its first overlapping leaf pair (enough to say "touching").
    refine_time_of_contact: continuous detector only. False returns the sphere-tree time of first
        contact (the paper's Eq. 2 at leaf spheres, conservative: never later than the meshes' own).
        True then advances it on the exact meshes (conservative advancement with exact distances,
        see `continuous.refine_time_of_contact`) to what `contact` calls contact.
    contact: what the refined time of first contact means (`continuous.refine_time_of_contact`):
        WITHIN_TOLERANCE (the simulator's): no later than the meshes' first contact and within
        `contact_tolerance_mm` of travel of it; meshes that end the step within that tolerance of
        each other may count as touching (where the speed bound cannot prove them apart, as for
        a turning tooth). INTERSECTING (the staging planner's): the first time the
        advancement finds the meshes intersecting, in [0, 1], its strides never shorter than
        `contact_tolerance_mm` of closing (a contact shallower than that can slip between two
        strides: the query's resolution); meshes that end the step just apart do not touch.
    contact_tolerance_mm: the refinement's tolerance (mm): of travel (WITHIN_TOLERANCE), or the
        shortest stride (INTERSECTING).
    touch_tolerance_mm: `contacts`: the exact and continuous detectors count two meshes this close
        (mm) as touching.
    drawn_leaves: continuous detector only. False leaves the result's leaf arrays empty: for a
        caller that asks only which pairs touch and when (the simulation's detection), placing the
        leaves for drawing at each pair's time of contact is work for nothing.
    """

    all_leaf_pairs: bool = True
    refine_time_of_contact: bool = False
    contact: str = WITHIN_TOLERANCE
    contact_tolerance_mm: float = 0.05
    touch_tolerance_mm: float = 0.05
    drawn_leaves: bool = True

    def __post_init__(self):
        if self.contact not in CONTACTS:
            raise CollisionError(None, "contact", f"unknown meaning of contact {self.contact!r}", f"use one of {', '.join(CONTACTS)}")


@dataclass(frozen=True, eq=False)
class PairResult:
    """What one detector found for one candidate pair of teeth (FDI `a`, `b`).

    touching: whether the detector reports contact (continuous: at some time in [0, 1)).
    leaf_pairs: (m, 2) int64 leaf indices (leaf level of tooth a's tree, of tooth b's tree).
    centers_a, centers_b: (m, 3) float64 mm, arch frame: the overlapping leaves' centres at the
        reported time (the end pose for discrete queries, the time of first contact for continuous).
    radii_a, radii_b: (m,) float64 mm.
    time_of_first_contact: continuous detector only, in [0, 1); None when no contact in the step.
    distance: exact detector only: the meshes' distance (mm), 0 when they intersect.
    """

    a: int
    b: int
    touching: bool
    leaf_pairs: np.ndarray
    centers_a: np.ndarray
    centers_b: np.ndarray
    radii_a: np.ndarray
    radii_b: np.ndarray
    time_of_first_contact: float | None = None
    distance: float | None = None


@dataclass(frozen=True, eq=False)
class StepResult:
    """Every candidate pair of one step, with the leaf arrays concatenated for drawing.

    pairs: (p, 2) int64 FDI numbers of the tested pairs, in the order given.
    touching: (p,) bool per pair.
    time_of_first_contact: (p,) float64 per pair, NaN where no contact (continuous detector, in
        [0, 1), or [0, 1] when refined to INTERSECTING meshes; NaN everywhere for discrete detectors).
    pair_of_leaf: (m,) int64 index into `pairs` of each overlapping leaf pair.
    leaf_pairs, centers_a, centers_b, radii_a, radii_b: as in `PairResult`, concatenated over pairs.
    detector: which detector produced this ("circles", "discrete", "continuous", "exact").
    distance: (p,) float64 mm per pair from the exact detector; empty (length 0) from the others,
        which measure no distance (`pair(i).distance` is then None).
    """

    detector: str
    pairs: np.ndarray
    touching: np.ndarray
    time_of_first_contact: np.ndarray
    pair_of_leaf: np.ndarray
    leaf_pairs: np.ndarray
    centers_a: np.ndarray
    centers_b: np.ndarray
    radii_a: np.ndarray
    radii_b: np.ndarray
    distance: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def any_touching(self) -> bool:
        return bool(self.touching.any())

    @property
    def first_time_of_contact(self) -> float | None:
        """Least time of first contact over all pairs of the step, None when nothing touches."""
        t = self.time_of_first_contact
        if t.size == 0 or np.all(np.isnan(t)):
            return None
        return float(np.nanmin(t))

    def touching_pairs(self) -> list[tuple[int, int]]:
        return [(a, b) for (a, b), hit in zip(self.pairs.tolist(), self.touching.tolist()) if hit]

    def first_contacts(self) -> list[tuple[tuple[int, int], float]]:
        """Each touching pair with the time (0-1 of the step) it is first found in contact: its time
        of first contact from a detector that sweeps the motion, the step's end (1.0) from one that
        tests the end poses."""
        times = self.time_of_first_contact.tolist() if len(self.time_of_first_contact) else [np.nan] * len(self.touching)
        return [((a, b), 1.0 if np.isnan(t) else float(t))
                for (a, b), hit, t in zip(self.pairs.tolist(), self.touching.tolist(), times) if hit]

    def pair(self, i: int) -> PairResult:
        """The result of pair i alone."""
        sel = self.pair_of_leaf == i
        toc = self.time_of_first_contact[i] if len(self.time_of_first_contact) else np.nan
        dist = self.distance[i] if len(self.distance) else np.nan
        return PairResult(
            a=int(self.pairs[i, 0]),
            b=int(self.pairs[i, 1]),
            touching=bool(self.touching[i]),
            leaf_pairs=self.leaf_pairs[sel],
            centers_a=self.centers_a[sel],
            centers_b=self.centers_b[sel],
            radii_a=self.radii_a[sel],
            radii_b=self.radii_b[sel],
            time_of_first_contact=None if np.isnan(toc) else float(toc),
            distance=None if np.isnan(dist) else float(dist),
        )

    def by_pair(self) -> dict[tuple[int, int], PairResult]:
        return {(int(a), int(b)): self.pair(i) for i, (a, b) in enumerate(self.pairs)}


@dataclass(frozen=True, eq=False)
class Contacts:
    """The contacts of one set of poses, as a detector sees them (`detect.contacts`).

    touching: pairs (FDI) in contact, in the order of the pairs asked about.

    centers (n, 3) mm, radii (n,) mm: what is drawn as contact: overlapping leaf spheres of the
        touching pairs (both teeth's) for the sphere-tree detectors, one lens sphere per pair for
        circles, none for the exact detector.
    penetration: pair -> mm for every pair asked about whose exact meshes interpenetrate, in the
        order of the pairs asked about (pairs apart are left out).
    distance: pair -> mm between the exact meshes, for the pairs whose distance decided contact
        (exact: every pair; continuous: the pairs whose leaf spheres overlap; none otherwise).
    """

    touching: tuple[tuple[int, int], ...]
    centers: np.ndarray
    radii: np.ndarray
    penetration: dict[tuple[int, int], float]
    distance: dict[tuple[int, int], float]


def empty_leaves() -> dict[str, np.ndarray]:
    return dict(
        pair_of_leaf=np.zeros(0, np.int64),
        leaf_pairs=np.zeros((0, 2), np.int64),
        centers_a=np.zeros((0, 3)),
        centers_b=np.zeros((0, 3)),
        radii_a=np.zeros(0),
        radii_b=np.zeros(0),
    )

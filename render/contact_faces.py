"""Exact contact faces for every frame of an animation, each answer computed once while it holds.

With `exact_contact_faces` a frame colours, on each tooth in contact, the triangles within the
touch tolerance (0.05 mm) of a tooth it touches (`orthosim.collision.contact_area`). Asked afresh
every frame, that costs most of a frame on real crowns of 40k triangles. Yet the answer for a
tooth depends only on its pose and the step's contact spheres (which triangles are candidates),
and for a pair on the two teeth's poses and those candidates; between two simulation steps the
frames share the step's contact spheres and only the moving teeth change pose. So answers are
kept by the bytes of what they depend on: a frame recomputes only the teeth whose pose changed
since an answer was kept (the moving teeth and the pairs they belong to), and every other face
comes from the answer computed for an earlier frame with the same inputs, bit for bit the same
faces. Answers of the current and the previous step are kept, no more. Poses (4, 4) local -> arch frame, mm.
"""

from __future__ import annotations

import hashlib

import numpy as np

from orthosim.collision.contact_area import ContactSurface, faces_in_spheres


def _digest(*arrays: np.ndarray) -> bytes:
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.digest()


class ExactContactFaces:
    """The touching faces of each tooth of one dentition, frame by frame, with answers kept while they hold.

    `computed` and `reused` count the pair answers computed and those taken from an earlier frame.
    """

    def __init__(self, dentition):
        self.dentition = dentition
        self.surfaces: dict[int, ContactSurface] = {}
        self._spheres: bytes | None = None
        self._candidates: dict[tuple, np.ndarray] = {}  # (fdi, pose bytes) -> candidate faces, this step's spheres
        self._pairs: dict[tuple, np.ndarray] = {}  # (fdi, pose, partner, pose, candidates digest) -> faces
        self._older_pairs: dict[tuple, np.ndarray] = {}  # the previous step's
        self.computed = self.reused = 0

    def surface(self, fdi: int) -> ContactSurface:
        if fdi not in self.surfaces:
            mesh = self.dentition.teeth[fdi].mesh
            self.surfaces[fdi] = ContactSurface(mesh.vertices, mesh.faces)
        return self.surfaces[fdi]

    def _use_spheres(self, centers: np.ndarray, radii: np.ndarray) -> None:
        key = _digest(centers, radii)
        if key != self._spheres:
            self._spheres = key
            self._candidates = {}
            self._older_pairs, self._pairs = self._pairs, {}

    def _candidates_of(self, fdi: int, pose: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, bytes]:
        key = (fdi, pose.tobytes())
        if key not in self._candidates:
            found = faces_in_spheres(self.surface(fdi), pose, centers, radii)
            self._candidates[key] = (found, _digest(found))
        return self._candidates[key]

    def _pair(self, fdi: int, pose: np.ndarray, candidates: np.ndarray, digest: bytes, partner: int,
              partner_pose: np.ndarray) -> np.ndarray:
        key = (fdi, pose.tobytes(), partner, partner_pose.tobytes(), digest)
        found = self._pairs.get(key)
        if found is None:
            found = self._older_pairs.get(key)
        if found is None:
            found = self.surface(fdi).faces_touching(candidates, pose, self.surface(partner), partner_pose)
            self.computed += 1
        else:
            self.reused += 1
        self._pairs[key] = found
        return found

    def faces(self, fdi: int, pose: np.ndarray, partners, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Sorted faces of tooth `fdi` at `pose` touching any of `partners` ((FDI, pose) pairs),
        among its faces wholly inside a contact sphere (`centers` (n, 3) arch frame mm, `radii` (n,) mm)."""
        self._use_spheres(centers, radii)
        pose = np.ascontiguousarray(pose, dtype=float)
        candidates, digest = self._candidates_of(fdi, pose, centers, radii)
        if not len(candidates):
            return candidates
        found = [self._pair(fdi, pose, candidates, digest, p, np.ascontiguousarray(p_pose, dtype=float))
                 for p, p_pose in partners]
        return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)

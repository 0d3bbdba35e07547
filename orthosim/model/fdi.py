"""FDI tooth numbering (ISO 3950): the two-digit names dentists use, and what each name implies.

The first digit is the quadrant (1 upper right, 2 upper left, 3 lower left, 4 lower right, all from
the patient's point of view), the second the position from the midline (1 central incisor ...
8 third molar). Universal (US) numbers, used by some datasets, map here too.
"""

from __future__ import annotations

from enum import Enum


class Arch(str, Enum):
    UPPER = "upper"  # maxillary
    LOWER = "lower"  # mandibular


class ToothType(str, Enum):
    CENTRAL_INCISOR = "central_incisor"
    LATERAL_INCISOR = "lateral_incisor"
    CANINE = "canine"
    FIRST_PREMOLAR = "first_premolar"
    SECOND_PREMOLAR = "second_premolar"
    FIRST_MOLAR = "first_molar"
    SECOND_MOLAR = "second_molar"
    THIRD_MOLAR = "third_molar"

    @property
    def is_anterior(self) -> bool:
        return self in (ToothType.CENTRAL_INCISOR, ToothType.LATERAL_INCISOR, ToothType.CANINE)

    @property
    def is_molar(self) -> bool:
        return self in (ToothType.FIRST_MOLAR, ToothType.SECOND_MOLAR, ToothType.THIRD_MOLAR)


TYPE_BY_POSITION = {
    1: ToothType.CENTRAL_INCISOR,
    2: ToothType.LATERAL_INCISOR,
    3: ToothType.CANINE,
    4: ToothType.FIRST_PREMOLAR,
    5: ToothType.SECOND_PREMOLAR,
    6: ToothType.FIRST_MOLAR,
    7: ToothType.SECOND_MOLAR,
    8: ToothType.THIRD_MOLAR,
}

QUADRANTS = (1, 2, 3, 4)
ALL_FDI: tuple[int, ...] = tuple(10 * q + p for q in QUADRANTS for p in range(1, 9))


def is_fdi(number: object) -> bool:
    return isinstance(number, int) and not isinstance(number, bool) and number in ALL_FDI


def quadrant(fdi: int) -> int:
    return fdi // 10


def position(fdi: int) -> int:
    """1 (central incisor) to 8 (third molar)."""
    return fdi % 10


def arch_of(fdi: int) -> Arch:
    return Arch.UPPER if quadrant(fdi) in (1, 2) else Arch.LOWER


def tooth_type(fdi: int) -> ToothType:
    return TYPE_BY_POSITION[position(fdi)]


def side(fdi: int) -> int:
    """-1 on the patient's right (quadrants 1 and 4, at negative x), +1 on the left."""
    return -1 if quadrant(fdi) in (1, 4) else 1


def arch_order(arch: Arch, present: set[int] | None = None) -> list[int]:
    """Teeth of one arch from the patient's right distal end to the left distal end (increasing x)."""
    if arch is Arch.UPPER:
        order = [10 + p for p in range(8, 0, -1)] + [20 + p for p in range(1, 9)]
    else:
        order = [40 + p for p in range(8, 0, -1)] + [30 + p for p in range(1, 9)]
    return [t for t in order if present is None or t in present]


def opposing_quadrant(fdi: int) -> int:
    return {1: 4, 2: 3, 3: 2, 4: 1}[quadrant(fdi)]


def universal_to_fdi(number: int) -> int:
    """Universal 1-16 (upper, patient's right third molar to left third molar), 17-32 (lower, left to right)."""
    if not 1 <= number <= 32:
        raise ValueError(f"Universal tooth numbers run 1 to 32, got {number}")
    if number <= 8:
        return 10 + (9 - number)
    if number <= 16:
        return 20 + (number - 8)
    if number <= 24:
        return 30 + (25 - number)
    return 40 + (number - 24)


def name(fdi: int) -> str:
    """Human-readable name, e.g. 16 -> 'upper right first molar'."""
    side_name = "right" if side(fdi) < 0 else "left"
    return f"{arch_of(fdi).value} {side_name} {tooth_type(fdi).value.replace('_', ' ')}"

"""Average tooth dimensions of the adult dentition (Wheeler's Dental Anatomy), in millimetres.

These numbers shape the parametric teeth and set the arch length; where Wheeler gives a range
(upper molar roots, 12-13 and 11-12 mm) the middle of the range is used.
"""

from __future__ import annotations

from dataclasses import dataclass

from orthosim.model.fdi import Arch, ToothType, arch_of, tooth_type


@dataclass(frozen=True)
class ToothDimensions:
    crown_height: float  # mm, cemento-enamel junction to incisal edge or cusp tip
    root_length: float  # mm, cemento-enamel junction to apex
    md_width: float  # mm, mesiodistal crown width (contact point to contact point)
    bl_width: float  # mm, buccolingual (labiolingual) crown width
    roots: int  # number of roots


_T = ToothType
WHEELER: dict[tuple[Arch, ToothType], ToothDimensions] = {
    (Arch.UPPER, _T.CENTRAL_INCISOR): ToothDimensions(10.5, 13.0, 8.5, 7.0, 1),
    (Arch.UPPER, _T.LATERAL_INCISOR): ToothDimensions(9.0, 13.0, 6.5, 6.0, 1),
    (Arch.UPPER, _T.CANINE): ToothDimensions(10.0, 17.0, 7.5, 8.0, 1),
    (Arch.UPPER, _T.FIRST_PREMOLAR): ToothDimensions(8.5, 14.0, 7.0, 9.0, 2),
    (Arch.UPPER, _T.SECOND_PREMOLAR): ToothDimensions(8.5, 14.0, 7.0, 9.0, 1),
    (Arch.UPPER, _T.FIRST_MOLAR): ToothDimensions(7.5, 12.5, 10.0, 11.0, 3),
    (Arch.UPPER, _T.SECOND_MOLAR): ToothDimensions(7.0, 11.5, 9.0, 11.0, 3),
    (Arch.UPPER, _T.THIRD_MOLAR): ToothDimensions(6.5, 11.0, 8.5, 10.0, 3),
    (Arch.LOWER, _T.CENTRAL_INCISOR): ToothDimensions(9.0, 12.5, 5.0, 6.0, 1),
    (Arch.LOWER, _T.LATERAL_INCISOR): ToothDimensions(9.5, 14.0, 5.5, 6.5, 1),
    (Arch.LOWER, _T.CANINE): ToothDimensions(11.0, 16.0, 7.0, 7.5, 1),
    (Arch.LOWER, _T.FIRST_PREMOLAR): ToothDimensions(8.5, 14.0, 7.0, 7.5, 1),
    (Arch.LOWER, _T.SECOND_PREMOLAR): ToothDimensions(8.0, 14.5, 7.0, 8.0, 1),
    (Arch.LOWER, _T.FIRST_MOLAR): ToothDimensions(7.5, 14.0, 11.0, 10.5, 2),
    (Arch.LOWER, _T.SECOND_MOLAR): ToothDimensions(7.0, 13.0, 10.5, 10.0, 2),
    (Arch.LOWER, _T.THIRD_MOLAR): ToothDimensions(7.0, 11.0, 10.0, 9.5, 2),
}


def dimensions(fdi: int) -> ToothDimensions:
    return WHEELER[(arch_of(fdi), tooth_type(fdi))]

"""Gear ratios from a robot's URDF: the ``<transmission>`` of a joint, in the classic form
(``<mechanicalReduction>`` under ``<actuator>`` or under ``<transmission>`` itself) and in the
ros2_control form (``<joint name=...><mechanical_reduction>``), read with the standard library's
XML parser.  :func:`gear_from_urdf` makes of it a one-stage gear train (kind ``other``) whose total
ratio is the reduction, for a recording given without a gear spec.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import InputError
from ..gears import GearTrain, Stage

__all__ = ["urdf_reductions", "urdf_reduction", "gear_from_urdf"]

#: where a transmission states its reduction, in the order looked at (ros2_control first)
_REDUCTION_PATHS = ("joint/mechanical_reduction", "joint/mechanicalReduction", "actuator/mechanicalReduction",
                    "actuator/mechanical_reduction", "mechanicalReduction", "mechanical_reduction")


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _parse(path: Path) -> ET.Element:
    if not path.is_file():
        raise InputError(f"--urdf {path}: no such file")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputError(f"--urdf {path}: not a valid XML file ({exc})") from None
    for el in root.iter():  # namespaced files: compare local names only
        el.tag = _local(el.tag)
    return root


def _number(path: Path, name: str, text: str | None) -> float:
    raw = (text or "").strip()
    try:
        value = float(raw)
    except ValueError:
        hint = "; it looks like a xacro expression: expand the file with xacro first" if "$" in raw else ""
        raise InputError(f"--urdf {path}: transmission '{name}': the mechanical reduction '{raw}' is not a "
                         f"number{hint}") from None
    if not math.isfinite(value) or value == 0:
        raise InputError(f"--urdf {path}: transmission '{name}': the mechanical reduction must be a finite, "
                         f"non-zero number, got {raw}")
    return value


def urdf_reductions(path: str | Path) -> dict[str, float]:
    """The mechanical reduction of every joint driven by a simple transmission of the URDF ``path``.

    Returns
    -------
    dict
        Joint name -> reduction (actuator turns per joint turn, dimensionless; negative when the
        transmission reverses the direction).  Joints of a transmission coupling several joints
        (differential, four-bar) are left out: no single ratio describes them.

    Raises
    ------
    InputError
        Unreadable XML, a reduction that is not a number, or one joint given two different reductions.
    """
    path = Path(path)
    root = _parse(path)
    out: dict[str, float] = {}
    for tr in root.iter("transmission"):
        name = tr.get("name", "?")
        joints = [j.get("name") for j in tr.findall("joint") if j.get("name")]
        if len(joints) != 1:
            continue
        found = next((el for p in _REDUCTION_PATHS for el in tr.findall(p)), None)
        if found is None:
            continue
        value = _number(path, name, found.text)
        joint = joints[0]
        if joint in out and out[joint] != value:
            raise InputError(f"--urdf {path}: joint '{joint}' has two transmissions with different reductions "
                             f"({out[joint]:g} and {value:g}); keep one")
        out[joint] = value
    return out


def urdf_reduction(path: str | Path, joint: str | None = None) -> tuple[str, float]:
    """The joint and its mechanical reduction from the URDF ``path`` (see :func:`urdf_reductions`);
    ``joint`` None is allowed when one joint only has a transmission."""
    path = Path(path)
    table = urdf_reductions(path)
    if not table:
        raise InputError(f"--urdf {path}: no <transmission> with a mechanical reduction for a single joint")
    if joint is None:
        if len(table) == 1:
            return next(iter(table.items()))
        raise InputError(f"--urdf {path}: transmissions for {len(table)} joints ({', '.join(table)}); say which "
                         "with --joint NAME")
    if joint not in table:
        raise InputError(f"--urdf {path}: no simple transmission with a mechanical reduction for joint '{joint}' "
                         f"(joints with one: {', '.join(table)})")
    return joint, table[joint]


def gear_from_urdf(path: str | Path, joint: str | None = None) -> tuple[GearTrain, str]:
    """A gear train of one stage (kind ``other``) whose total ratio is the joint's reduction in the
    URDF ``path``, and the sentence that says so.

    ``theta`` of a joint state is the joint (output) position, so the train's reference is the
    output shaft; a negative reduction (direction reversed) gives its magnitude as the ratio.
    """
    joint, value = urdf_reduction(path, joint)
    ratio = abs(value)
    note = f"gear ratio {ratio:g} from URDF {path}, joint {joint}"
    if value < 0:
        note += " (the reduction is negative: the transmission reverses the direction)"
    gear = GearTrain(name=f"{joint} (URDF)", reference="output", stages=(Stage("transmission", "other", ratio),),
                     description=note, source=f"URDF {path}")
    return gear, note

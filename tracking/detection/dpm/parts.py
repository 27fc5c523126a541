"""Names for the parts of a person model, from where their anchors sit in the root window.

voc-release5 parts are anonymous filters; their anchors say which body region each covers. A
part's anchor centre, relative to the root's detection window, is
``u = (ax + w / 2) / (2 W)`` across and ``v = (ay + h / 2) / (2 H)`` down (parts have twice the
root resolution: ``W, H`` root cells are ``2 W, 2 H`` part cells). The name is the vertical band
of ``v`` and the side of ``u``:

======================  ============  ===================  ==================
``v``                   ``u < 0.4``   ``0.4 <= u <= 0.6``  ``u > 0.6``
======================  ============  ===================  ==================
``< 0.2``               head          head                 head
``0.2 .. 0.4``          left_shoulder torso                right_shoulder
``0.4 .. 0.6``          left_hip      pelvis               right_hip
``0.6 .. 0.8``          left_knee     knees                right_knee
``>= 0.8``              left_foot     feet                 right_foot
======================  ============  ===================  ==================

**Left and right are the image's**: ``left_shoulder`` is the shoulder on the left of the picture
(smaller x), which is the person's right shoulder when they face the camera. A mirrored
component's part ``i`` is the mirror image of the original's part ``i``, so its anchor sits on
the other side and gets the other side's name: each name always denotes the same region of the
box (e.g. its upper left), whichever component fired. Two parts of a component in the same
region are told apart by a suffix (``head``, ``head_2``).

For the INRIA person model the eight parts are: head, left_shoulder, right_shoulder, left_hip,
right_hip, right_knee (left_knee in the mirrored component), left_foot, right_foot.
"""

from __future__ import annotations

from tracking.detection.dpm.model import DpmComponent, DpmModel

__all__ = ["component_part_names", "model_part_names"]

_BANDS = (
    (0.2, ("head", "head", "head")),
    (0.4, ("left_shoulder", "torso", "right_shoulder")),
    (0.6, ("left_hip", "pelvis", "right_hip")),
    (0.8, ("left_knee", "knees", "right_knee")),
    (float("inf"), ("left_foot", "feet", "right_foot")),
)
_ORDER = tuple(name for _, names in _BANDS for name in dict.fromkeys(names))


def _region(u: float, v: float) -> str:
    side = 0 if u < 0.4 else (2 if u > 0.6 else 1)
    for limit, names in _BANDS:
        if v < limit:
            return names[side]
    raise AssertionError("unreachable")  # the last band is unbounded


def component_part_names(component: DpmComponent) -> tuple[str, ...]:
    """The name of each part of ``component``, in its ``parts`` order."""
    root_h, root_w = component.window
    names: list[str] = []
    for part in component.parts:
        ax, ay, ds = part.anchor
        scale = 2**ds
        h, w = part.size
        u = (ax + w / 2) / (scale * root_w)
        v = (ay + h / 2) / (scale * root_h)
        base = _region(u, v)
        name, n = base, 1
        while name in names:
            n += 1
            name = f"{base}_{n}"
        names.append(name)
    return tuple(names)


def _rank(name: str) -> tuple[int, int, str]:
    """Sort key: region order of :data:`_BANDS`, then the duplicate suffix."""
    base, suffix = name, 1
    head, _, tail = name.rpartition("_")
    if head and tail.isdigit():
        base, suffix = head, int(tail)
    return (_ORDER.index(base) if base in _ORDER else len(_ORDER), suffix, name)


def model_part_names(model: DpmModel) -> tuple[tuple[str, ...], tuple[tuple[int, ...], ...]]:
    """The detector's part names and, per component, the slot of each of its parts.

    Returns
    -------
    names : tuple of str
        The union of the components' part names, head to feet, image-left to image-right.
    slots : tuple of tuple of int
        ``slots[c][i]`` is the index in ``names`` of part ``i`` of component ``c``.
    """
    per_component = [component_part_names(c) for c in model.components]
    union = sorted({n for names in per_component for n in names}, key=_rank)
    index = {n: i for i, n in enumerate(union)}
    return tuple(union), tuple(tuple(index[n] for n in names) for names in per_component)

"""The robot a scenario or design space of several segments describes (design/README.md, "Several
segments"): each segment's wires evenly spaced, segment ``j``'s turned so that no two holes of a disk
meet (:func:`interleaved_angles`), and every wire crossing a proximal segment through that segment's
disk, on its hole circle (the segment's pitch radius), at the wire's own angle.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ..model._design import Design
from ..model._robot import Robot


def interleaved_angles(counts) -> list[np.ndarray]:
    """Each segment's wire angles (rad), evenly spaced, segment ``j``'s turned by ``2 pi j / (S lcm)``
    (``lcm`` of the counts): no two holes of a disk meet, and with equal counts the first disk's
    holes are evenly spaced. ``counts`` (S,) wires per segment, proximal first."""
    S, lcm = len(counts), math.lcm(*counts)
    return [np.arange(n) * (2 * np.pi / n) + 2 * np.pi * j / (S * lcm) for j, n in enumerate(counts)]


def hole_gaps(angles) -> list[float]:
    """The smallest angle (rad) between two holes of each segment's disk, (S,): its own wires' and every
    distal segment's, which cross it on its hole circle (``angles``: each segment's wire angles)."""
    out = []
    for j in range(len(angles)):
        a = np.sort(np.mod(np.concatenate(angles[j:]), 2 * np.pi))
        out.append(float(np.min(np.diff(np.concatenate([a, a[:1] + 2 * np.pi])))))
    return out


def chain(counts, length, pitch_radius, **fields) -> Robot:
    """The robot of ``counts`` wires per segment with each segment's length, pitch radius and other
    ``fields`` (Design field names), (S,) each: concrete values, checked as a :class:`Design` checks
    them."""
    angles = interleaved_angles(counts)
    segs = [
        Design(n, length[j], pitch_radius[j], angles[j], **{f: v[j] for f, v in fields.items()})
        for j, n in enumerate(counts)
    ]
    return with_numbers(Robot(segs))


def per_segment(robot: Robot, field: str):
    """A :class:`Design` field of each segment, (S,)."""
    return jnp.stack([jnp.asarray(getattr(s, field)) for s in robot.segments])


def with_numbers(base: Robot, **fields) -> Robot:
    """``base`` with each segment's ``fields`` replaced (Design field names, (S,) each), every wire
    crossing segment ``j`` on its hole circle: traced, vmapped or concrete."""
    segs = [s.replace(**{f: v[j] for f, v in fields.items()}) for j, s in enumerate(base.segments)]
    r = jnp.stack([jnp.asarray(s.pitch_radius) for s in segs])
    return Robot(segs, base.route_angles, jnp.broadcast_to(r, base.route_radii.shape))

"""Simple shapes for carving packings: Box, Plate, Sphere, Cylinder.

Each has ``contains(pos_nc) -> (N,) bool`` and ``bounds() -> (lo_c, hi_c)``
(Angstrom).
"""

from dataclasses import dataclass

import numpy as np

from ..errors import InputError


def _vec3(name, v):
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, v, "three finite numbers (Angstrom)") from None
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(name, v, "three finite numbers (Angstrom)")
    return a


@dataclass
class Box:
    """Axis-aligned box [lo, hi)."""
    lo: tuple
    hi: tuple

    def __post_init__(self):
        self.lo = _vec3("lo", self.lo)
        self.hi = _vec3("hi", self.hi)
        if np.any(self.hi <= self.lo):
            raise InputError("hi", self.hi.tolist(), f"each component > lo = {self.lo.tolist()}")

    def contains(self, pos):
        return np.all((pos >= self.lo) & (pos < self.hi), axis=1)

    def bounds(self):
        return self.lo.copy(), self.hi.copy()


@dataclass
class Sphere:
    center: tuple
    radius: float

    def __post_init__(self):
        self.center = _vec3("center", self.center)
        if not self.radius > 0:
            raise InputError("radius", self.radius, "a positive length")

    def contains(self, pos):
        return ((pos - self.center) ** 2).sum(axis=1) < self.radius ** 2

    def bounds(self):
        return self.center - self.radius, self.center + self.radius


@dataclass
class Cylinder:
    """Cylinder of ``radius`` around ``axis`` (0, 1, 2 = x, y, z) from ``start`` over ``length``."""
    center: tuple
    radius: float
    length: float
    axis: int = 0

    def __post_init__(self):
        self.center = _vec3("center", self.center)
        if not self.radius > 0:
            raise InputError("radius", self.radius, "a positive length")
        if not self.length > 0:
            raise InputError("length", self.length, "a positive length")
        if self.axis not in (0, 1, 2):
            raise InputError("axis", self.axis, "0, 1 or 2 (x, y, z)")

    def contains(self, pos):
        rel = pos - self.center
        ax = rel[:, self.axis]
        other = [d for d in range(3) if d != self.axis]
        r2 = (rel[:, other] ** 2).sum(axis=1)
        return (r2 < self.radius ** 2) & (ax >= 0) & (ax < self.length)

    def bounds(self):
        lo = self.center - self.radius
        hi = self.center + self.radius
        lo[self.axis] = self.center[self.axis]
        hi[self.axis] = self.center[self.axis] + self.length
        return lo, hi


def Plate(thickness, width, axis=0, origin=(0.0, 0.0, 0.0)):
    """A plate: a box of ``thickness`` along ``axis`` and ``width`` (scalar or pair) across."""
    o = _vec3("origin", origin)
    w = np.broadcast_to(np.asarray(width, dtype=float), (2,))
    ext = np.empty(3)
    ext[axis] = thickness
    ext[[d for d in range(3) if d != axis]] = w
    return Box(o, o + ext)

"""The minimum-image convention of an orthorhombic box (periodic along some axes).

One definition for every force model and analysis: along a periodic axis of
length L a separation ``dx`` becomes ``dx - L floor(dx/L + 1/2)``, in
``[-L/2, L/2)``; along an open axis it is unchanged.  The box comes from
:func:`~clusterdyn.neighbors.check_cell` (lengths ``box_c`` and flags
``periodic_c``).
"""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def image_component(dx, length):
    """One Cartesian component of a separation, wrapped to ``[-L/2, L/2)`` (numba; L > 0)."""
    return dx - length * math.floor(dx / length + 0.5)


def minimum_image(d_pc, box_c, periodic_c):
    """Wrap separations ``d_pc`` (P, 3) in place along the periodic axes; returns ``d_pc``.

    Parameters
    ----------
    d_pc : (P, 3) float64 array, Angstrom
        Separations ``x_j - x_i``.
    box_c : (3,) float64, Angstrom
        Box lengths.
    periodic_c : (3,) bool
        Periodic axes.
    """
    for a in range(3):
        if periodic_c[a]:
            d_pc[:, a] -= box_c[a] * np.floor(d_pc[:, a] / box_c[a] + 0.5)
    return d_pc

"""Time-step limits of Cluster Dynamics: the stability limit of velocity Verlet on a cluster
lattice, the default time step, and the check of a step against the stiffness of the closest
pair (used by :class:`clusterdyn.md.DampedVerlet`)."""

import math

import numpy as np

from ..errors import InstabilityError

#: default time step as a fraction of r0/(c0 + u_max); see :func:`default_timestep`
TIMESTEP_FACTOR = 0.03
#: grid points of the scan for the distance below which a pair's stiffness limits the time step
SAFE_GRID = 400


def stability_limit(calc, r_over_r0=1.0):
    """Velocity-Verlet stability limit of an fcc cluster lattice, ASE time.

    ``dt_max = 2/omega_max`` with ``omega_max^2 = 8 k/m`` (k = -f'(r) at the
    given r/r0, 1 = at rest), the smallest over the materials.  About
    0.58 r0/c0 at rest; it shrinks as compression stiffens the bonds.
    """
    lim = math.inf
    for p in calc.potentials:
        k = float(p.stiffness(r_over_r0 * p.r0))
        if k > 0:
            lim = min(lim, 2.0 / math.sqrt(8.0 * k / p.mass))
    return lim


def pair_stability_limit(calc, a, b, r):
    """Stability limit ``2/omega_max`` of a lattice whose bonds are as stiff as the
    (a, b) pair law at distance r (``omega_max^2 = 8 k/m`` with the lighter
    cluster's mass); unlike pairs use their series law.  ``r`` may be an array."""
    law = calc.law(a, b)
    if a == b:
        k = np.asarray(law.stiffness(r), dtype=float)
    else:
        h = 1e-4 * law.r0
        k = -(np.asarray(law.force(r + h), dtype=float) - np.asarray(law.force(r - h), dtype=float)) / (2.0 * h)
    m = min(calc.masses_t[a], calc.masses_t[b])
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = np.where(k > 0, 2.0 / np.sqrt(np.where(k > 0, 8.0 * k / m, 1.0)), np.inf)
    return float(lim) if lim.ndim == 0 else lim


def default_timestep(calc, u_max=0.0, factor=TIMESTEP_FACTOR):
    """``factor * min(r0 / (c0 + u_max))`` over the materials (ASE time).

    The default factor 0.03 is 1/19 of the stability limit at rest
    (:func:`stability_limit`, 0.58 r0/c0).  The margin is set by accuracy,
    not stability: velocity Verlet's energy error is an O((omega dt)^2)
    offset, and 0.03 keeps it below 1e-3 of the kinetic energy of a thermal
    lattice (0.1 would give 0.75%).  At u = 3 km/s in aluminium it gives
    0.019 r0/c0, the step of the method's reference runs; the ``u_max`` term
    keeps the margin in shocks, where compression raises the sound speed
    (measured by ``clusterdyn study stability``).
    """
    return factor * min(p.r0 / (p.c0 + abs(u_max)) for p in calc.potentials)


class StiffnessCheck:
    """The time step ``dt`` against the limit set by the closest pair's own bond stiffness.

    The distance below which a pair law's limit falls under ``dt`` is scanned once per pair
    type (on a grid of :data:`SAFE_GRID` points from the table's smallest distance to r0, plus
    one grid spacing), so a step pays one comparison; the exact limit is evaluated only below it.
    """

    def __init__(self, calc, dt):
        self.calc = calc
        self.dt = dt
        self._safe = {}

    def safe_distance(self, a, b):
        """Distance above which the (a, b) pair law's stability limit exceeds the time step."""
        r = self._safe.get((a, b))
        if r is None:
            table = self.calc.tables[a][b]
            lo = table.r_min
            grid = np.linspace(lo, table.law.r0, SAFE_GRID)
            lim = pair_stability_limit(self.calc, a, b, grid)
            bad = grid[self.dt > lim]
            r = (bad.max() if bad.size else lo) + (grid[1] - grid[0])
            self._safe[(a, b)] = r
        return r

    def __call__(self, stats, material, at):
        """Check the pass whose ``last_stats`` are ``stats`` (``material``: the particles' ids or
        None) at step ``at``; raises InstabilityError when the step is above the limit."""
        x = stats["min_r_over_r0"]
        if x >= 1.0 or not math.isfinite(x):
            return
        if material is None or len(self.calc.potentials) == 1:
            a, b = 0, 0  # one pair law: the closest pair is named only if the check fails
        else:
            i, j = stats["closest"]
            a, b = int(material[i]), int(material[j])
        r = x * self.calc.law(a, b).r0
        if r > self.safe_distance(a, b):
            return
        lim = pair_stability_limit(self.calc, a, b, r)
        if self.dt > lim:
            raise InstabilityError(
                "time step above the stability limit at the current compression "
                f"(closest pair at r = {x:.3f} r0); lower the time step", step=at,
                particles=stats["closest"], quantity="timestep", value=self.dt, limit=lim)

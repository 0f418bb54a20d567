"""Slab profiles along an axis: density, velocity, stress (virial + kinetic) and its intensity.

Conventions (docs/theory.md, stress): stresses are tension-positive, Voigt
xx yy zz yz xz xy in eV/Angstrom^3; the kinetic part is taken about each
slab's mean velocity.
"""

import numpy as np

from ..errors import InputError
from .stress import particle_virials, pressure, von_mises


def binned_profile(atoms, virials=None, axis=0, width=None, lo=None, hi=None, exclude=None):
    """Profiles of density, velocity and stress in slabs normal to ``axis``.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic (or at least with a 3-D cell) across the two other axes; the
        cross-section is the cell's.
    virials : (N, 6) array, optional
        Per-particle potential virials (Voigt xx yy zz yz xz xy, eV), e.g.
        ``calc.get_property('virials', atoms)``.  Without them only the
        kinetic part of the stress is returned.
    width : float
        Slab width, Angstrom.
    lo, hi : float
        Range along ``axis`` (default: the particles' extent).
    exclude : bool mask, optional
        Particles left out (e.g. a piston layer).

    Returns
    -------
    dict with ``x`` (slab centres), ``count``, ``mass``, ``density`` (amu/A^3),
    ``velocity`` ((nb, 3) mean velocity, A/time), ``stress`` ((nb, 6) virial +
    kinetic, eV/A^3, tension positive, lab-frame Voigt xx yy zz yz xz xy),
    ``pressure`` ((nb,) mean pressure ``-tr(stress)/3``), ``von_mises`` ((nb,)
    stress intensity of CD eq. 4, :func:`clusterdyn.analysis.stress.von_mises`),
    ``width``, ``area``.
    """
    pos = atoms.positions[:, axis]
    m = atoms.get_masses()
    v = atoms.get_velocities()
    keep = np.ones(len(atoms), bool) if exclude is None else ~np.asarray(exclude, bool)
    if lo is None:
        lo = pos[keep].min()
    if hi is None:
        hi = pos[keep].max() + 1e-9 * max(1.0, abs(pos).max())
    nb = max(1, int(np.ceil((hi - lo) / width)))
    edges = lo + width * np.arange(nb + 1)
    idx = np.floor((pos - lo) / width).astype(np.int64)
    keep &= (idx >= 0) & (idx < nb)
    idx = idx[keep]
    mk, vk = m[keep], v[keep]
    others = [d for d in range(3) if d != axis]
    cell = atoms.cell.array
    area = abs(np.linalg.det(cell[np.ix_(others, others)])) if atoms.cell.rank == 3 else np.nan
    vol = area * width
    count = np.bincount(idx, minlength=nb)
    mass = np.bincount(idx, weights=mk, minlength=nb)
    mom = np.stack([np.bincount(idx, weights=mk * vk[:, c], minlength=nb) for c in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        vel = mom / mass[:, None]
    vel[mass == 0] = 0.0
    dv = vk - vel[idx]
    pairs = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    stress = np.zeros((nb, 6))
    for c, (p, q) in enumerate(pairs):
        stress[:, c] = -np.bincount(idx, weights=mk * dv[:, p] * dv[:, q], minlength=nb)
        if virials is not None:
            stress[:, c] += np.bincount(idx, weights=np.asarray(virials)[keep, c], minlength=nb)
    stress /= vol
    return {"x": 0.5 * (edges[1:] + edges[:-1]), "edges": edges, "count": count, "mass": mass,
            "density": mass / vol, "velocity": vel, "stress": stress, "pressure": pressure(stress),
            "von_mises": von_mises(stress), "width": width, "area": area}


def stress_profile(atoms, width, virials=None, axis=0, lo=None, hi=None, exclude=None):
    """Slab profile along ``axis`` of the six stress components and the intensity.

    Wraps :func:`binned_profile` (slabs of ``width``
    across the cell's cross-section, kinetic part about each slab's mean
    velocity) and adds ``von_mises`` (nb,) and ``pressure`` (nb,).  Components
    stay in the lab frame whatever ``axis`` is.

    Returns
    -------
    dict
        ``x`` (nb,), ``stress`` (nb, 6) eV/A^3, ``von_mises``, ``pressure``,
        ``density``, ``velocity`` (nb, 3), ``count``, ``edges``, ``width``, ``area``.
    """
    if atoms.cell.rank != 3:
        raise InputError("atoms.cell", atoms.cell, "a 3-D cell: its cross-section is the slab area")
    W = particle_virials(atoms) if virials is None else virials
    prof = binned_profile(atoms, W, axis=axis, width=width, lo=lo, hi=hi, exclude=exclude)
    prof["von_mises"] = von_mises(prof["stress"])
    prof["pressure"] = pressure(prof["stress"])
    return prof

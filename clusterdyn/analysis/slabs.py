"""Slab profiles along an axis: density, velocity, stress (virial + kinetic) and its intensity.

Conventions (docs/theory.md, stress): stresses are tension-positive, Voigt
xx yy zz yz xz xy in eV/Angstrom^3; the kinetic part is taken about each
slab's mean velocity.
"""

import numpy as np

from ..errors import InputError
from .stress import particle_virials, pressure, von_mises


def occupied_area(atoms, idx, keep, axis, nb, grid):
    """Per slab, the area the material occupies on the slab's plane: the number of cells of a
    ``grid`` x ``grid`` mesh on that plane holding at least one of the slab's particles, times
    ``grid**2``.  ``idx``: slab of each kept particle; ``keep``: mask of the particles binned."""
    others = [d for d in range(3) if d != axis]
    q = atoms.positions[keep][:, others]
    if len(q) == 0:
        return np.zeros(nb)
    cij = np.floor((q - q.min(axis=0)) / grid).astype(np.int64)
    ny = int(cij[:, 1].max()) + 1
    key = (idx * (int(cij[:, 0].max()) + 1) + cij[:, 0]) * ny + cij[:, 1]
    uniq = np.unique(key)
    slab = uniq // ((int(cij[:, 0].max()) + 1) * ny)
    return np.bincount(slab, minlength=nb) * grid * grid


def _grid_length(atoms):
    r0 = atoms.info.get("cd_r0")
    if r0:
        return float(min(r0))
    if "radius" in atoms.arrays:
        return float(2.0 * np.min(atoms.arrays["radius"]))
    raise InputError("grid", None, "a mesh size (no cd_r0 in atoms.info and no radius array to take r0 from)")


def binned_profile(atoms, virials=None, axis=0, width=None, lo=None, hi=None, exclude=None, area=None,
                   grid=None):
    """Profiles of density, velocity and stress in slabs normal to ``axis``.

    The volume of a slab is its width times an area: ``area="cell"`` the cell's
    cross-section (exact for a sample periodic across the two other axes),
    ``area="occupied"`` the area the material occupies on the slab's plane
    (:func:`occupied_area`: the cells of an r0 mesh holding a particle of the
    slab; for a rod, a sphere or a debris cloud in an open box), or a number
    (Angstrom^2).  Default: "cell" when both other axes are periodic, else
    "occupied".

    Parameters
    ----------
    atoms : ase.Atoms
        With a 3-D cell when the area is the cell's.
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
    area : "cell", "occupied", float or (nb,) array, optional
        Cross-section of the slabs (see above).
    grid : float, optional
        Mesh size of the occupied area, Angstrom (default r0: ``min(atoms.info['cd_r0'])``
        or twice the smallest ``radius``).

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
    if area is None:
        area = "cell" if all(atoms.pbc[d] for d in others) else "occupied"
    if isinstance(area, str):
        if area == "cell":
            cell = atoms.cell.array
            area = abs(np.linalg.det(cell[np.ix_(others, others)])) if atoms.cell.rank == 3 else np.nan
        elif area == "occupied":
            area = occupied_area(atoms, idx, keep, axis, nb, _grid_length(atoms) if grid is None else grid)
        else:
            raise InputError("area", area, "'cell', 'occupied' or an area in Angstrom^2")
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
    with np.errstate(invalid="ignore", divide="ignore"):
        stress /= np.reshape(vol, (-1, 1)) if np.ndim(vol) else vol
        density = mass / vol
    return {"x": 0.5 * (edges[1:] + edges[:-1]), "edges": edges, "count": count, "mass": mass,
            "density": density, "velocity": vel, "stress": stress, "pressure": pressure(stress),
            "von_mises": von_mises(stress), "width": width, "area": area}


def stress_profile(atoms, width, virials=None, axis=0, lo=None, hi=None, exclude=None, area=None, grid=None):
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
    others = [d for d in range(3) if d != axis]
    cell_area = area == "cell" or (area is None and all(atoms.pbc[d] for d in others))
    if cell_area and atoms.cell.rank != 3:
        raise InputError("atoms.cell", atoms.cell, "a 3-D cell: its cross-section is the slab area "
                         "(or area='occupied')")
    W = particle_virials(atoms) if virials is None else virials
    prof = binned_profile(atoms, W, axis=axis, width=width, lo=lo, hi=hi, exclude=exclude, area=area, grid=grid)
    prof["von_mises"] = von_mises(prof["stress"])
    prof["pressure"] = pressure(prof["stress"])
    return prof

"""Two-phase samples: spherical inclusions of one material in a matrix of another (docs/theory.md 1.6).

The CD paper's two cases (r0 = 4 um for both phases unless a study shows
better):

* h-BN matrix (72 mass %) with B4C spheres of ~56 um:
  ``two_phase("h-BN", "B4C", 0.28, 56 * units.um)``
* B4C matrix (75 mass %) with h-BN spheres of ~56 um:
  ``two_phase("B4C", "h-BN", 0.25, 56 * units.um)``

Unlike pairs need nothing here: the calculator builds the unlike-pair law
(two half-bonds in series, docs/theory.md 1.2) and the dynamics the per-pair
damping for any pair of material ids.
"""

import math

import numpy as np
from scipy.spatial import cKDTree

from .. import units
from ..errors import InputError, check_positive
from ..materials import get_material
from .lattice import (SQRT2, check_size, fcc_sites, make_cluster_atoms, orientation_matrix, parse_direction,
                      repeat_lengths)

#: the CD paper's two-phase samples: (matrix, inclusion, inclusion mass fraction, sphere diameter)
PAPER_CASES = {
    "hBN-B4C": ("h-BN", "B4C", 0.28, 56.0 * units.um),
    "B4C-hBN": ("B4C", "h-BN", 0.25, 56.0 * units.um),
}


def volume_fraction(mass_fraction, rho_inclusion, rho_matrix):
    """Volume fraction of the inclusions for a mass fraction (fully dense phases)."""
    vi = mass_fraction / rho_inclusion
    vm = (1.0 - mass_fraction) / rho_matrix
    return vi / (vi + vm)


def _min_image(d, L, periodic):
    d = d.copy()
    for k in range(3):
        if periodic[k]:
            d[..., k] -= L[k] * np.round(d[..., k] / L[k])
    return d


def place_spheres(box, diameters, gap=0.0, periodic=(True, True, True), seed=1, max_tries=20000):
    """Random sequential placement of non-overlapping spheres in a box (largest first).

    Parameters
    ----------
    box : (3,) array
        Box lengths, Angstrom (origin at 0).
    diameters : (n,) array
        Sphere diameters, Angstrom.
    gap : float
        Smallest surface-to-surface distance between two spheres, Angstrom.
    periodic : 3 bools
        Directions in which spheres wrap (minimum image); in the others the
        spheres lie wholly inside the box.
    seed : int
        The placement is a pure function of its arguments and the seed.

    Returns
    -------
    (n, 3) array of centres, in the order of ``diameters``.
    """
    L = np.asarray(box, float)
    d = np.asarray(diameters, float)
    periodic = np.asarray(periodic, bool)
    rng = np.random.default_rng(seed)
    order = np.argsort(-d, kind="stable")
    centres = np.full((len(d), 3), np.nan)
    placed = []
    for k in order:
        R = 0.5 * d[k]
        lo = np.where(periodic, 0.0, R)
        hi = np.where(periodic, L, L - R)
        if np.any(hi < lo):
            raise InputError("inclusion_diameter", d[k] / units.um,
                             f"a sphere that fits in the box ({np.round(L / units.um, 1).tolist()} um) "
                             "along the non-periodic directions")
        for _ in range(max_tries):
            c = lo + rng.random(3) * (hi - lo)
            if placed:
                P = centres[placed]
                r = np.linalg.norm(_min_image(P - c, L, periodic), axis=1)
                if np.any(r < 0.5 * (d[placed] + d[k]) + gap):
                    continue
            centres[k] = c
            placed.append(k)
            break
        else:
            raise InputError("mass_fraction", f"{len(d)} spheres",
                             f"a packing the random placement can reach: sphere {len(placed) + 1} of "
                             f"{len(d)} found no free place after {max_tries} tries (lower the fraction, "
                             "the diameter or the gap, or enlarge the sample)")
    # periodic directions: centres wrapped into the box
    centres = np.where(periodic, np.mod(centres, L), centres)
    return centres


def two_phase(matrix, inclusion, mass_fraction, inclusion_diameter, r0=4 * units.um, size=(60, 12, 12),
              direction=(1, 0, 0), pbc=(False, True, True), seed=1, r0_inclusion=None,
              diameter_spread=0.0, gap=0.0, d_min=0.9):
    """A block of ``matrix`` clusters with spherical ``inclusion`` particles, fcc packed.

    Parameters
    ----------
    matrix, inclusion : str or Material
        Material of the matrix (id 0) and of the spheres (id 1).
    mass_fraction : float
        Target mass fraction of the inclusion phase, in (0, 1) (the paper's
        h-BN matrix of 72 mass % has ``mass_fraction=0.28`` of B4C).
    inclusion_diameter : float
        Mean sphere diameter, Angstrom.
    r0 : float
        Cluster size of the matrix (and of the inclusions unless
        ``r0_inclusion``), Angstrom.
    size : (nx, ny, nz)
        Orthorhombic repeat cells of the matrix lattice along x, y, z
        (x = ``direction``); the box is ``size * repeat_lengths``.
    direction : [100] | [110] | [111]
        Crystal direction along x.
    pbc : 3 bools
        Periodic directions of the Atoms.  Spheres are placed as in a
        periodic block in all three directions (a sample cut from it), so
        the inclusion content is uniform along x on average.
    seed : int
        Seed of the placement (and of the diameters): same seed, same sample.
    r0_inclusion : float, optional
        Cluster size inside the spheres.  Equal sizes (default) put both
        phases on one lattice, coherent across the interface.  A different
        size fills each sphere with its own lattice and removes matrix
        clusters closer than ``d_min * (r0 + r0_inclusion)/2`` to an inclusion cluster.
    diameter_spread : float
        Relative standard deviation of the diameters (0 = all equal);
        diameters are drawn from a normal law clipped to +- 2 spreads.
    gap : float, optional
        Smallest distance between two sphere surfaces, Angstrom (default 0: spheres may touch).

    Returns
    -------
    ase.Atoms
        Arrays ``material`` (0 matrix, 1 inclusion), ``radius``, ``id``;
        ``atoms.info['two_phase']`` holds the target and achieved mass and
        volume fractions, the sphere centres and diameters (Angstrom) and
        ``rho0`` (mean density at rest, amu/Angstrom^3).
    """
    mat_m, mat_i = get_material(matrix), get_material(inclusion)
    for name, m in (("matrix", mat_m), ("inclusion", mat_i)):
        if m.curve is None:
            raise InputError(name, m.name, "a material with a cold curve (CD)")
    try:
        w = float(mass_fraction)
    except (TypeError, ValueError):
        raise InputError("mass_fraction", mass_fraction, "a number in (0, 1)") from None
    if not 0.0 < w < 1.0:
        raise InputError("mass_fraction", mass_fraction, "a number in (0, 1)")
    D = check_positive("inclusion_diameter", inclusion_diameter)
    r0 = check_positive("r0", r0)
    r0i = r0 if r0_inclusion is None else check_positive("r0_inclusion", r0_inclusion)
    gap = float(gap)
    if not 0.0 <= diameter_spread < 0.5:
        raise InputError("diameter_spread", diameter_spread, "a relative spread in [0, 0.5)")
    key = parse_direction(direction)
    size = check_size(size)
    R = orientation_matrix(key)
    L = repeat_lengths(key, r0) * np.array(size)
    V = float(np.prod(L))
    phi = volume_fraction(w, mat_i.rho0, mat_m.rho0)
    diam = _sphere_diameters(D, diameter_spread, phi * V, seed)
    if not diam:
        raise InputError("mass_fraction", w, f"enough inclusion volume for one sphere of {D / units.um:g} um "
                         f"in this sample ({np.round(L / units.um, 1).tolist()} um); enlarge the sample")
    diam = np.array(diam)
    if np.any(diam >= L.min()):
        raise InputError("inclusion_diameter", D / units.um,
                         f"a diameter below the smallest box length ({L.min() / units.um:.4g} um)")
    centres = place_spheres(L, diam, gap=gap, periodic=(True, True, True), seed=seed)
    pos, mid = _two_phase_sites(r0, r0i, R, L, centres, diam, d_min)
    atoms = make_cluster_atoms(pos, [mat_m, mat_i], [r0, r0i], material_id=mid, cell=np.diag(L), pbc=pbc)
    atoms.info["direction"] = key
    m = atoms.get_masses()
    vrest = np.where(mid == 1, r0i ** 3, r0 ** 3) / SQRT2
    achieved = float(m[mid == 1].sum() / m.sum())
    atoms.info["two_phase"] = {
        "matrix": mat_m.name, "inclusion": mat_i.name,
        "mass_fraction_target": w, "mass_fraction": achieved,
        "volume_fraction_target": float(phi), "volume_fraction": float(vrest[mid == 1].sum() / vrest.sum()),
        "n_spheres": int(len(diam)), "diameters": diam, "centres": centres, "seed": int(seed),
        "rho0": float(m.sum() / vrest.sum()),
        "n_matrix": int((mid == 0).sum()), "n_inclusion": int((mid == 1).sum()),
    }
    return atoms


def _sphere_diameters(D, spread, target, seed):
    """Sphere diameters of mean ``D`` (relative spread ``spread``, normal law clipped to +- 2
    spreads), drawn until their volume is nearest ``target``: a list (empty when not even
    half a sphere fits the target)."""
    rng = np.random.default_rng([seed, 7])
    diam, vol = [], 0.0
    while vol < target:
        d = D * (1.0 + spread * float(np.clip(rng.normal(), -2, 2))) if spread else D
        v = math.pi / 6.0 * d ** 3
        if vol + 0.5 * v > target and diam:        # nearest total to the target
            break
        diam.append(d)
        vol += v
    return diam


def _sphere_labels(pts, L, centres, diam):
    """Index of the sphere holding each point (-1: none), periodic box ``L``."""
    tree = cKDTree(np.mod(pts, L), boxsize=L)
    lab = np.full(len(pts), -1, np.int64)
    for k, (c, d) in enumerate(zip(centres, diam)):
        idx = tree.query_ball_point(np.mod(c, L), 0.5 * d)
        lab[idx] = k
    return lab


def _two_phase_sites(r0, r0i, R, L, centres, diam, d_min):
    """The clusters of both phases, sorted by position: (positions, material ids).  Equal sizes:
    one lattice, its sites in a sphere are inclusion clusters; else each phase its own lattice,
    matrix clusters closer than ``d_min (r0 + r0i)/2`` to an inclusion cluster left out."""
    matrix_sites = fcc_sites(r0, R, np.zeros(3), L)
    if r0i == r0:
        lab = _sphere_labels(matrix_sites, L, centres, diam)
        pos = matrix_sites
        mid = (lab >= 0).astype(np.int64)
    else:
        inc = fcc_sites(r0i, R, np.zeros(3), L)
        inc = inc[_sphere_labels(inc, L, centres, diam) >= 0]
        keep = _sphere_labels(matrix_sites, L, centres, diam) < 0
        m_sites = matrix_sites[keep]
        if len(inc):
            tree = cKDTree(np.mod(inc, L), boxsize=L)
            dist, _ = tree.query(np.mod(m_sites, L))
            m_sites = m_sites[dist >= d_min * 0.5 * (r0 + r0i)]
        pos = np.vstack([m_sites, inc])
        mid = np.concatenate([np.zeros(len(m_sites), np.int64), np.ones(len(inc), np.int64)])
    order = np.lexsort((pos[:, 2], pos[:, 1], pos[:, 0]))
    return pos[order], mid[order]


def rest_volumes(atoms):
    """Volume of each cluster at rest, ``r0^3 / sqrt(2)`` from ``arrays['radius']`` (Angstrom^3)."""
    r = atoms.arrays.get("radius")
    if r is None:
        raise InputError("atoms.arrays['radius']", None, "cluster radii r0/2 (set by clusterdyn builders)")
    return (2.0 * np.asarray(r)) ** 3 / SQRT2

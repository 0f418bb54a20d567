"""fcc packings of clusters (CD), oriented and carved.

An fcc packing of clusters of size r0 has lattice constant ``a = sqrt(2) r0``,
12 neighbours at r0 and 4 clusters per cubic cell; each cluster has mass
``rho0 r0^3 / sqrt(2)`` so the packing has the material's density.
"""

import math

import numpy as np
from ase import Atoms
from ase.data import atomic_numbers

from ..errors import InputError, check_positive
from ..materials import get_material

SQRT2 = math.sqrt(2.0)

#: longitudinal sound speed of the nearest-neighbour fcc cluster lattice along a direction, in c0
#: (docs/theory.md 1.5: C11 = 2k/a along [100], rho c^2 = 5k/(2a) along [110], 8k/(3a) along [111])
LATTICE_CL = {"100": math.sqrt(1.5), "110": math.sqrt(15.0 / 8.0), "111": math.sqrt(2.0)}


def lattice_sound_speed(c0, direction="100"):
    """Longitudinal sound speed c_L of the cluster lattice along ``direction`` ("100", "110" or "111"):
    ``LATTICE_CL[direction] * c0`` (sqrt(3/2) c0 along [100]), in the units of ``c0``."""
    return LATTICE_CL[direction] * c0

#: orthogonal right-handed (x, y, z) Miller directions for the shock directions offered
ORIENTATIONS = {
    (1, 0, 0): ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    (1, 1, 0): ((1, 1, 0), (-1, 1, 0), (0, 0, 1)),
    (1, 1, 1): ((1, 1, 1), (1, -1, 0), (1, 1, -2)),
}
_FCC_BASIS = np.array([[0, 0, 0], [0, .5, .5], [.5, 0, .5], [.5, .5, 0]])


def parse_direction(direction):
    """(1,0,0) | "100" | "[110]" | 111 -> tuple key of ORIENTATIONS."""
    s = str(direction) if not isinstance(direction, (tuple, list, np.ndarray)) else None
    if s is not None:
        s = s.strip("[]() ").replace(",", "").replace(" ", "")
        if len(s) == 3 and s.isdigit():
            direction = tuple(int(c) for c in s)
    try:
        key = tuple(int(v) for v in direction)
    except (TypeError, ValueError):
        key = None
    if key not in ORIENTATIONS:
        raise InputError("direction", direction, "one of [100], [110], [111] (e.g. (1, 0, 0) or '110')")
    return key


def orientation_matrix(direction):
    """Rotation R (rows = unit x, y, z directions in crystal coordinates) for a shock direction."""
    rows = np.array(ORIENTATIONS[parse_direction(direction)], dtype=float)
    return rows / np.linalg.norm(rows, axis=1)[:, None]


def repeat_lengths(direction, r0):
    """Lengths of the smallest orthorhombic periodic cell of an oriented fcc packing."""
    a = SQRT2 * r0
    key = parse_direction(direction)
    rows = np.array(ORIENTATIONS[key], dtype=float)
    # period along an integer direction [h k l] of fcc: a*|hkl| if h+k+l even... use the general rule
    out = []
    for v in rows:
        v = v.astype(int)
        g = np.gcd.reduce(np.abs(v[v != 0]))
        v = v // g
        # translation a*v/2 is an fcc lattice vector iff sum of v even (all of v/2 on the lattice)
        if (v.sum() % 2 == 0):
            out.append(a * np.linalg.norm(v) / 2.0)
        else:
            out.append(a * np.linalg.norm(v))
    return np.array(out)


def check_size(size):
    """Validate (nx, ny, nz) repeat counts: three positive integers."""
    try:
        out = tuple(int(s) for s in size)
    except (TypeError, ValueError):
        raise InputError("size", size, "three positive integers (repeat cells along x, y, z)") from None
    if len(out) != 3 or min(out) < 1:
        raise InputError("size", size, "three positive integers (repeat cells along x, y, z)")
    return out


def fcc_sites(r0, rotation, lo, hi):
    """fcc sites (cluster centres) of lattice constant sqrt(2) r0 in the box [lo, hi).

    Parameters
    ----------
    r0 : float
        Nearest-neighbour distance, Angstrom.
    rotation : (3, 3) array
        Lab = rotation @ crystal (columns: crystal axes in the lab frame).
    lo, hi : (3,) arrays
        Box corners, Angstrom.
    origin of the lattice: lab point ``lo``.
    """
    a = SQRT2 * r0
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    R = np.asarray(rotation, float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])]) - lo
    crys = corners @ R          # crystal coordinates of the corners (R orthogonal)
    cmin = np.floor(crys.min(axis=0) / a) - 1
    cmax = np.ceil(crys.max(axis=0) / a) + 1
    ranges = [np.arange(cmin[d], cmax[d] + 1) for d in range(3)]
    grid = np.array(np.meshgrid(*ranges, indexing="ij")).reshape(3, -1).T
    pts = (grid[:, None, :] + _FCC_BASIS[None, :, :]).reshape(-1, 3) * a
    lab = pts @ R.T + lo
    eps = 1e-9 * r0
    inside = np.all((lab >= lo - eps) & (lab < hi - eps), axis=1)
    return lab[inside]


def make_cluster_atoms(positions, materials, r0s, material_id=None, cell=None, pbc=False):
    """Atoms of clusters with the per-particle arrays every CD kernel reads.

    Arrays: ``material`` (int), ``radius`` (r0/2), ``id`` (stable 0..N-1);
    ``atoms.info['cd_materials']`` (names) and ``['cd_r0']`` (Angstrom) per material id.
    Masses are ``rho0 r0^3/sqrt(2)``.
    """
    materials = [get_material(m) for m in materials]
    r0s = [check_positive("r0", r) for r in np.atleast_1d(r0s)]
    if len(r0s) == 1 and len(materials) > 1:
        r0s = r0s * len(materials)
    n = len(positions)
    mid = np.zeros(n, dtype=np.int64) if material_id is None else np.asarray(material_id, np.int64)
    numbers = np.array([atomic_numbers.get(m.name, 0) for m in materials])[mid] if n else []
    atoms = Atoms(numbers=numbers, positions=positions, cell=cell, pbc=pbc)
    mass = np.array([m.rho0 * r ** 3 / SQRT2 for m, r in zip(materials, r0s)])
    atoms.set_masses(mass[mid] if n else [])
    atoms.new_array("material", mid.astype(np.int64))
    atoms.new_array("radius", (0.5 * np.array(r0s))[mid] if n else np.zeros(0))
    atoms.new_array("id", np.arange(n, dtype=np.int64))
    atoms.info["cd_materials"] = [m.name for m in materials]
    atoms.info["cd_r0"] = [float(r) for r in r0s]
    return atoms


def fcc_packing(material, r0, size=(4, 4, 4), direction=(1, 0, 0), pbc=False, shape=None):
    """fcc packing of clusters of one material.

    Parameters
    ----------
    material : Material or str
    r0 : float
        Cluster size (nearest-neighbour distance), Angstrom.
    size : (nx, ny, nz) ints
        Number of orthorhombic repeat cells along x, y, z (for [100], cubic
        cells of 4 clusters: N = 4 nx ny nz).
    direction : [100] | [110] | [111]
        Crystal direction along x.
    pbc : bool or 3 bools
        Periodic directions; the cell is the repeat box either way.
    shape : Box | Sphere | Cylinder | None
        If given, the lattice fills the shape's bounding box and is carved
        to it (``size`` is ignored); the cell is that bounding box.

    Returns
    -------
    ase.Atoms with arrays ``material``, ``radius``, ``id``.

    Raises
    ------
    clusterdyn.errors.InputError
        ``material`` has no cold curve (an MCA material: build its automata
        with :func:`clusterdyn.build.mca_packing`).
    """
    mat = get_material(material)
    if mat.curve is None:
        from ..materials import cd_material_names
        raise InputError("material", getattr(mat, "name", material), "a Cluster Dynamics material (with a cold "
                         "curve): " + ", ".join(cd_material_names()),
                         hint="an MCA material: build its automata with clusterdyn.build.mca_packing")
    r0 = check_positive("r0", r0)
    key = parse_direction(direction)
    R = orientation_matrix(key)     # rows: lab axes in crystal coordinates
    rot = R                          # crystal -> lab: lab = R @ crystal
    lengths = repeat_lengths(key, r0)
    if shape is None:
        size = check_size(size)
        lo = np.zeros(3)
        hi = lengths * np.array(size)
        pos = fcc_sites(r0, rot, lo, hi)
        cell = np.diag(hi)
    else:
        lo, hi = shape.bounds()
        pos = fcc_sites(r0, rot, lo, hi)
        pos = pos[shape.contains(pos)]
        cell = np.diag(hi - lo)
        if len(pos) == 0:
            raise InputError("shape", shape, f"a shape that holds at least one cluster of r0={r0:.4g} A")
    order = np.lexsort((pos[:, 2], pos[:, 1], pos[:, 0]))
    atoms = make_cluster_atoms(pos[order], [mat], [r0], cell=cell, pbc=pbc)
    atoms.info["direction"] = key
    return atoms


def along_axis(atoms, axis):
    """Turn a sample built along x so that its x axis lies along ``axis`` (0, 1, 2 or x, y, z).

    A cyclic permutation of the coordinates (x -> axis, y -> axis+1, ...), so
    the handedness and the crystal orientation relative to the new axis are
    kept; positions, momenta, cell and pbc are permuted in place and the
    Atoms is returned.  ``atoms.info['axis']`` records the axis.
    """
    ax = parse_axis(axis)
    if ax:
        inv = (np.arange(3) - ax) % 3             # new column j <- old column j - axis
        p = atoms.get_momenta() if "momenta" in atoms.arrays else None
        atoms.positions = atoms.positions[:, inv]
        atoms.set_cell(atoms.cell.array[np.ix_(inv, inv)], scale_atoms=False)
        atoms.pbc = np.asarray(atoms.pbc)[inv]
        if p is not None:
            atoms.set_momenta(p[:, inv], apply_constraint=False)
    atoms.info["axis"] = "xyz"[ax]
    return atoms


def parse_axis(axis):
    """0, 1, 2 or 'x', 'y', 'z' -> 0, 1, 2 (InputError otherwise)."""
    if isinstance(axis, str) and axis.strip().lower() in ("x", "y", "z"):
        return "xyz".index(axis.strip().lower())
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= int(axis) <= 2:
        return int(axis)
    raise InputError("axis", axis, "x, y or z (or 0, 1, 2)")

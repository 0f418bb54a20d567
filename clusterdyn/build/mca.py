"""Builders of MCA samples: packings (fcc, hcp, sc, random; 2D hex, square, random), notches, pre-cracks.

Every builder returns ``ase.Atoms`` with the arrays the MCA needs:
``radius`` (d/2), ``id`` (stable 0..N-1), ``material`` (int), ``omega`` and
``theta`` (zeros), masses ``rho * V_cell`` (the Voronoi cell of the automaton
clipped at the sample surface), ``info['mca_materials']`` and ``info['mca_dim']``.

Box samples: ``shape = (Lx, Ly, Lz)`` in Angstrom (2D: ``(Lx, Ly)``); each
length is rounded down to whole periods of the lattice (at least one), the
cell is the resulting box and the sites sit half a layer from its faces, so
the free-surface tessellation (geometry.py) is exact.  Other shapes
(:mod:`clusterdyn.build.shapes` Box, Sphere, Cylinder) are carved from the
packing of their bounding box.

Random packing (``packing="random"``): monodisperse dense random packing by
a force-biased relaxation: ``N = round(phi V / v_sphere)`` centres (phi = 0.60
by default, below random close packing 0.64) are placed uniformly at random
(``numpy.random.default_rng(seed)``) and repeatedly pushed apart along the
line of centres of every overlapping pair (half the overlap each, with a
relaxation factor), and kept at least d/2 from the faces of open directions,
until the largest overlap is below 1e-3 d (or 2000 sweeps).  The result is
jammed-like, isotropic and reproducible for a given seed.
"""

import math

import numpy as np
from ase import Atoms
from scipy.spatial import cKDTree

from ..errors import InputError, check_positive
from ..materials import get_material
from .tessellation import tessellate
from ..materials.mca import check_mca_material

PACKINGS_3D = ("fcc", "hcp", "sc", "random")
PACKINGS_2D = ("hex", "sc", "random")


def _lattice(packing, d, dim):
    """Orthorhombic repeat cell (lengths) and fractional basis; layer offsets from the faces."""
    if dim == 3:
        if packing == "sc":
            return np.array([d, d, d]), np.array([[0.5, 0.5, 0.5]])
        if packing == "fcc":
            a = math.sqrt(2.0) * d
            b = np.array([[0, 0, 0], [0, .5, .5], [.5, 0, .5], [.5, .5, 0]]) + 0.25
            return np.array([a, a, a]), b
        if packing == "hcp":
            a = d
            c = math.sqrt(8.0 / 3.0) * d
            b = np.array([[0, 0, 0], [.5, .5, 0], [.5, 1 / 6, .5], [0, 2 / 3, .5]])
            b = b + np.array([0.25, 1 / 12, 0.25])
            return np.array([a, math.sqrt(3.0) * a, c]), b
    else:
        if packing == "sc":
            return np.array([d, d]), np.array([[0.5, 0.5]])
        if packing == "hex":
            a = d
            b = np.array([[0, 0], [.5, .5]]) + np.array([0.25, 0.25])
            return np.array([a, math.sqrt(3.0) * a]), b
    raise InputError("packing", packing, "one of " + ", ".join(PACKINGS_3D if dim == 3 else PACKINGS_2D))


def random_packing(d, lengths, pbc, phi=None, seed=0, max_sweeps=2000):
    """Monodisperse dense random packing (see module docstring). Returns (N, dim) centres."""
    dim = len(lengths)
    L = np.asarray(lengths, float)
    if phi is None:
        phi = 0.60 if dim == 3 else 0.82
    vs = math.pi / 6 * d ** 3 if dim == 3 else math.pi / 4 * d ** 2
    n = int(round(phi * np.prod(L) / vs))
    if n < dim + 2:
        raise InputError("shape", tuple(L), f"a box holding at least {dim + 2} automata of size {d:g}")
    rng = np.random.default_rng(seed)
    x = rng.random((n, dim)) * L
    per = np.asarray(pbc, bool)[:dim]
    lo = np.where(per, -np.inf, 0.5 * d)
    hi = np.where(per, np.inf, L - 0.5 * d)
    x = np.clip(x, np.where(per, 0, lo), np.where(per, L, hi))
    box = np.where(per, L, 0.0)
    for sweep in range(max_sweeps):
        xs = x.copy()
        for a in range(dim):
            if per[a]:
                xs[:, a] %= L[a]
        if per.any():
            bs = np.where(per, L, 1e9 * L.max())
            tree = cKDTree(np.mod(xs, bs) if per.all() else _shift_open(xs, per, bs), boxsize=bs)
        else:
            tree = cKDTree(xs)
        pairs = tree.query_pairs(d, output_type="ndarray")
        if len(pairs) == 0:
            break
        i, j = pairs[:, 0], pairs[:, 1]
        dv = x[j] - x[i]
        for a in range(dim):
            if per[a]:
                dv[:, a] -= L[a] * np.round(dv[:, a] / L[a])
        r = np.linalg.norm(dv, axis=1)
        ov = d - r
        if ov.max() < 1e-3 * d:
            break
        u = dv / np.maximum(r, 1e-12 * d)[:, None]
        mv = np.zeros_like(x)
        np.add.at(mv, i, -0.55 * ov[:, None] * u)
        np.add.at(mv, j, 0.55 * ov[:, None] * u)
        x += mv
        x = np.clip(x, lo, hi)
    for a in range(dim):
        if per[a]:
            x[:, a] %= L[a]
    return x


def _shift_open(xs, per, bs):
    out = xs.copy()
    for a in range(len(per)):
        if not per[a]:
            out[:, a] = xs[:, a] - xs[:, a].min() + 1.0
    return out


def mca_packing(material, d, shape, packing="fcc", pbc=False, seed=0, phi=None, materials=None,
                material_id=None):
    """A packing of automata of size ``d`` (Angstrom).

    Parameters
    ----------
    material : Material or name (e.g. ``"alumina"``), used when ``materials`` is None
    d : float, automaton size (nearest-neighbour distance), Angstrom
    shape : (Lx, Ly, Lz) or (Lx, Ly) box lengths (Angstrom; 2 entries = 2D plane
        strain, z = 0), or a shape from :mod:`clusterdyn.build.shapes`
    packing : "fcc" | "hcp" | "sc" | "random" (3D); "hex" | "sc" | "random" (2D;
        "fcc" and "hcp" mean "hex" there)
    pbc : bool or 3 bools
    seed : int, random packing seed; phi : packing fraction of the random packing
    materials : list of materials for multi-phase samples, with ``material_id``
        an (N,) array or a callable ``f(positions) -> ids``

    Returns
    -------
    ase.Atoms (see module docstring)
    """
    d = check_positive("d", d)
    mats = [check_mca_material(get_material(m)) for m in (materials or [material])]
    shp = None
    if hasattr(shape, "contains"):
        shp = shape
        lo, hi = shape.bounds()
        lengths = hi - lo
        dim = 3
    else:
        try:
            lengths = np.array([float(v) for v in shape])
        except (TypeError, ValueError):
            raise InputError("shape", shape, "(Lx, Ly, Lz) or (Lx, Ly) in Angstrom, or a Box/Sphere/Cylinder") from None
        if len(lengths) not in (2, 3) or not np.all(lengths > 0):
            raise InputError("shape", shape, "2 or 3 positive lengths (Angstrom)")
        dim = len(lengths)
        lo = np.zeros(dim)
    pbc3 = np.broadcast_to(np.asarray(pbc, bool), (3,)).copy()
    if dim == 2:
        pbc3[2] = False
        if packing in ("fcc", "hcp"):
            packing = "hex"
    if packing not in (PACKINGS_3D if dim == 3 else PACKINGS_2D):
        raise InputError("packing", packing, "one of " + ", ".join(PACKINGS_3D if dim == 3 else PACKINGS_2D))
    if packing == "random":
        L = lengths.copy()
        pos = random_packing(d, L, pbc3, phi=phi, seed=seed)
    else:
        per, basis = _lattice(packing, d, dim)
        reps = np.maximum(1, np.floor(lengths / per + 1e-9)).astype(int)
        if shp is not None:
            reps = np.ceil(lengths / per - 1e-9).astype(int)
        L = reps * per
        grid = np.array(np.meshgrid(*[np.arange(k) for k in reps], indexing="ij")).reshape(dim, -1).T
        pos = ((grid[:, None, :] + basis[None]) * per).reshape(-1, dim)
    if dim == 2:
        pos = np.column_stack([pos, np.zeros(len(pos))])
        cell = np.diag([L[0], L[1], 0.0])
    else:
        cell = np.diag(L)
    if shp is not None:
        pos = pos + lo
        keep = shp.contains(pos)
        if not keep.any():
            raise InputError("shape", shape, f"a shape that holds at least one automaton of size {d:g}")
        pos = pos[keep] - lo
    order = np.lexsort(tuple(pos[:, a] for a in range(2, -1, -1)))
    pos = pos[order]
    n = len(pos)
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=cell, pbc=pbc3)
    if material_id is None:
        mid = np.zeros(n, np.int64)
    elif callable(material_id):
        mid = np.asarray(material_id(pos), np.int64)
    else:
        mid = np.asarray(material_id, np.int64)
    if len(mid) != n or (n and (mid.min() < 0 or mid.max() >= len(mats))):
        raise InputError("material_id", mid, f"{n} ids in [0, {len(mats) - 1}]")
    atoms.new_array("radius", np.full(n, 0.5 * d))
    atoms.new_array("id", np.arange(n, dtype=np.int64))
    atoms.new_array("material", mid)
    atoms.new_array("omega", np.zeros((n, 3)))
    atoms.new_array("theta", np.zeros((n, 3)))
    atoms.info["mca_materials"] = mats
    atoms.info["mca_dim"] = dim
    atoms.info["mca_packing"] = packing
    atoms.info["mca_d"] = d
    if shp is not None and dim == 3 and not pbc3.any():
        # a shape carved from the lattice: its surface is not a cell face, so the cells are
        # closed by ghosts at the body's own surface (build.tessellation.tessellate_body), for
        # the masses and the MCA state alike (mirror planes at the box would give the surface
        # automata cells out to the box: a 6-across cylinder weighed 1.9 times its mass)
        atoms.info["mca_closure"] = "body"
    set_masses(atoms)
    return atoms


def set_masses(atoms):
    """Masses ``rho * V_cell`` from the tessellation (2D: area times unit thickness)."""
    dim = atoms.info.get("mca_dim", 3)
    if atoms.info.get("mca_closure") == "body":
        from .tessellation import tessellate_body
        g = tessellate_body(atoms.positions, atoms.arrays["radius"], dim)
    else:
        g = tessellate(atoms.positions, atoms.arrays["radius"], atoms.cell.array, atoms.pbc, dim)
    rho = np.array([m.rho0 for m in atoms.info["mca_materials"]])[atoms.arrays["material"]]
    atoms.set_masses(rho * g["vcell_n"])
    return atoms


def precrack(atoms, point, normal, extent=None):
    """Pre-crack: pairs whose segment crosses the plane (point, normal) start unlinked.

    ``extent``: None (the whole plane) or half-lengths (3,) of the crack region
    around ``point`` along x, y, z (Angstrom; the component along the normal is
    ignored).  Recorded in ``atoms.info['mca_cracks']`` and applied when the
    MCA state is built.  Returns ``atoms``.
    """
    n = np.asarray(normal, float)
    if n.shape != (3,) or not np.linalg.norm(n) > 0:
        raise InputError("normal", normal, "a non-zero 3-vector")
    c = {"point": np.asarray(point, float), "normal": n / np.linalg.norm(n),
         "extent": None if extent is None else np.asarray(extent, float)}
    atoms.info.setdefault("mca_cracks", []).append(c)
    return atoms


def notch(atoms, point, normal, width, extent):
    """Remove the automata within ``width/2`` of the plane (point, normal) inside ``extent``
    (half-lengths per axis, Angstrom): a notch.  Returns a new Atoms (ids kept)."""
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    rel = atoms.positions - np.asarray(point, float)
    dist = np.abs(rel @ n)
    inside = np.all(np.abs(rel) <= np.asarray(extent, float) + np.abs(n) * 1e30, axis=1)
    keep = ~((dist <= 0.5 * width) & inside)
    out = atoms[keep]
    out.info = dict(atoms.info)
    return out

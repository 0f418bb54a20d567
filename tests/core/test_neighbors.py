"""The Verlet list against a brute-force O(N^2) search (open and periodic orthorhombic boxes)."""

import itertools

import numpy as np
import pytest

from clusterdyn.build import fcc_packing
from clusterdyn.errors import InputError
from clusterdyn.neighbors import NeighborList


def brute_force(pos, L, pbc, rc):
    """All (i, j, image) with |x_j + image*L - x_i| < rc, i != j or image != 0."""
    out = set()
    n = len(pos)
    ranges = [range(-int(np.ceil(rc / L[d])) - 1, int(np.ceil(rc / L[d])) + 2) if pbc[d] else [0]
              for d in range(3)]
    for img in itertools.product(*ranges):
        s = np.array(img) * L
        d = pos[None, :, :] + s[None, None, :] - pos[:, None, :]
        r = np.sqrt((d ** 2).sum(-1))
        ii, jj = np.nonzero(r < rc)
        for i, j in zip(ii, jj):
            if i == j and img == (0, 0, 0):
                continue
            out.add((int(i), int(j)) + tuple(np.round(d[i, j], 7)))
    return out


def listed(nl, pos, rc):
    i, j, d, r = nl.pairs(pos)
    k = r < rc
    return {(int(a), int(b)) + tuple(np.round(c, 7)) for a, b, c in zip(i[k], j[k], d[k])}


def full_from_half(nl, pos, rc):
    i, j, d, r = nl.pairs(pos)
    k = r < rc
    s = set()
    for a, b, c in zip(i[k], j[k], d[k]):
        s.add((int(a), int(b)) + tuple(np.round(c, 7)))
        s.add((int(b), int(a)) + tuple(np.round(-c, 7)))
    return s, int(k.sum())


@pytest.mark.parametrize("seed", range(12))
def test_random_configurations(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 120))
    L = rng.uniform(1.0, 6.0, 3)
    pbc = rng.random(3) < 0.5
    rc = rng.uniform(0.4, 2.5)
    pos = rng.uniform(0, 1, (n, 3)) * L
    pos[: n // 4] = np.round(pos[: n // 4] / L * 3) / 3 * L        # particles on cell faces
    pos[n // 8: n // 4, 0] = 0.0
    ref = brute_force(pos, L, pbc, rc)
    skin = rng.uniform(0, 0.5)
    full = NeighborList(rc, skin, half=False)
    full.build(pos, np.diag(L), pbc)
    assert listed(full, pos, rc) == ref
    half = NeighborList(rc, skin, half=True)
    half.build(pos, np.diag(L), pbc)
    s, npairs = full_from_half(half, pos, rc)
    assert s == ref and 2 * npairs == len(ref)


@pytest.mark.parametrize("pbc", [(True, True, True), (False, True, True), (False, False, False)])
@pytest.mark.parametrize("size", [(1, 1, 1), (2, 1, 2), (3, 2, 4)])
def test_lattice_thin_boxes(pbc, size):
    atoms = fcc_packing("Al", 1.0, size=size, pbc=pbc)
    L = np.diag(atoms.cell.array)
    rc = 1.15
    ref = brute_force(atoms.positions, L, pbc, rc)
    nl = NeighborList(rc, 0.2, half=True)
    nl.build(atoms.positions, atoms.cell.array, pbc)
    s, _ = full_from_half(nl, atoms.positions, rc)
    assert s == ref
    if all(pbc):
        assert all(len([p for p in ref if p[0] == i]) == 12 for i in range(len(atoms)))


def test_rebuild_by_displacement():
    atoms = fcc_packing("Al", 1.0, size=(3, 3, 3), pbc=True)
    nl = NeighborList(1.15, 0.2)
    assert nl.update(atoms.positions, atoms.cell.array, atoms.pbc)
    pos = atoms.positions.copy()
    pos[5] += [0.09, 0, 0]
    assert not nl.update(pos, atoms.cell.array, atoms.pbc)
    pos[5] += [0.02, 0, 0]
    assert nl.update(pos, atoms.cell.array, atoms.pbc)
    assert nl.nbuilds == 2
    # particles that left the periodic box are wrapped by the list, not by us
    pos[7] += [3 * atoms.cell[0, 0], 0, 0]
    nl.update(pos, atoms.cell.array, atoms.pbc)
    s, _ = full_from_half(nl, pos, 1.15)
    L = np.diag(atoms.cell.array)
    assert s == brute_force(pos % L, L, atoms.pbc, 1.15)     # separations do not depend on wrapping


def test_non_orthorhombic_periodic_cell_refused():
    nl = NeighborList(1.0)
    cell = [[3, 0, 0], [1, 3, 0], [0, 0, 3]]
    with pytest.raises(InputError, match="orthorhombic"):
        nl.build(np.zeros((2, 3)), cell, True)
    nl.build(np.array([[0, 0, 0], [0.5, 0, 0]]), cell, False)        # open: the cell does not matter
    assert nl.npairs == 1

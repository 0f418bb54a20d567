"""Cell list + Verlet list with skin, numba kernels (open and periodic orthorhombic boxes).

The list is CSR over particles (like ASE's ``first_neighbors``):
pairs of particle ``i`` are ``p in range(first_n[i], first_n[i+1])`` with
partner ``j_p[p]`` and image code ``img_p[p]``.  The separation vector
used by every kernel is

    d = (pos[j] + offset[j]) - (pos[i] + offset[i]) + image_sc[img_p[p]]

where ``offset_nc`` wraps each particle into the periodic box at build time
(positions themselves are never changed) and ``image_sc`` holds the
Cartesian lattice translations.  A half list stores every unordered pair once
(``i < j``, or ``i == j`` with a positive image for boxes narrower than the
cutoff); a full list stores both directions.

The list is rebuilt when any particle has moved more than ``skin/2`` since
the last build (or, with ``centered=True``, when in addition the spread of
the displacements exceeds it), or when the cell or pbc changed.

With ``sort=True`` (the Cluster Dynamics calculator's list) the particles are
held in cell order: row k of the list is particle ``perm_n[k]``, positions
are gathered into that order every step (:func:`gather_positions`) and the
half list is built in a single pass over the own cell and the 13 forward
cells of the 3x3x3 stencil.  The caller's arrays are never reordered.
"""

import math

import numpy as np

from ..buffers import PERMUTE_WORDS, grown, permute
from ..errors import InputError
from ..parallel import use_threads
from .fill import (FILL_BLOCK_ROWS, HALF_RUNS, HALF_SHIFT, SLAB_MARGIN, _carried_need, _cell_blocks,
                   _close_slabs, _compact_rows, _fill_slabs, _pack, _search)
from .grid import (DENSE_CELLS_PER_PARTICLE, MAX_CELLS_PER_PARTICLE, _bin_particles, _box_key, _layer_rows,
                   _wrap, check_cell)
from .rebuild import (BRICK_SIDE, DISP_BLOCKS, MAX_BRICKS, MAX_BRICK_REACH, PARTICLES_PER_BRICK,
                      _assign_bricks, _brick_boxes, _brick_centres, _brick_chunks, _brick_radii, _bricks_safe,
                      _displacement, _max_disp2, _renumber_bricks)
from .sort import _identity, _is_identity, _sort_rows, gather_positions


class NeighborList:
    """Verlet list with skin, built on a cell list (numba).

    Parameters
    ----------
    cutoff : float
        Interaction cutoff, Angstrom (largest over pair types).
    skin : float, default 0
        Extra radius; the list stays valid while no pair separation can have
        changed by more than ``skin``.
    half : bool, default True
        Store each unordered pair once (``True``) or both directions.
    sort : bool, default False
        Hold the particles in cell order (:attr:`perm_n`): the list, the wrap
        offsets and the kernels' positions are over sorted rows, so a pair
        loop reads memory nearly in sequence.  The Atoms are never reordered;
        :meth:`pairs` and :attr:`offset_nc` answer in the caller's order.  A
        sorted half list on a grid with >= 3 cells along every periodic axis is
        built in one pass over the own cell and 13 forward cells, its pairs
        packed as ``j | image code << shift`` (:attr:`jp_p`).
    centered : bool, default False
        Rebuild test.  False: when a particle moved more than ``skin/2`` since
        the last build.  True: when both that and the half-diagonal of the
        bounding box of all displacements exceed ``skin/2`` (any common
        translation is subtracted, so a block moving as a whole, e.g. the
        material behind a shock front, triggers no rebuild of its own).  Both
        are rigorous: no pair closer than the cutoff is ever missing.
    cells : {"auto", "dense", "sparse"}
        Cell structure of a sorted list.  "dense": an array over every cell of
        the bounding box; "sparse": only the occupied cells, sorted by key
        (radix sort), their neighbours found by a forward walk over them, so
        memory and time are O(N) however far the particles spread.  "auto"
        (default): dense while the bounding box has at most
        :data:`DENSE_CELLS_PER_PARTICLE` cells per particle, else sparse.  Both
        give the same list in the same order.

    Attributes
    ----------
    first_n : (N+1,) int64
        CSR offsets (see module docstring); over sorted rows when ``sort``.
    j_p : (P,) int32, img_p : (P,) int16
        Partner and image code of each pair (decoded from :attr:`jp_p` for sorted lists).
    jp_p : (P,) uint32 or None
        Sorted lists: ``j | img << img_shift`` (the form the kernels read).
    img_shift : int
        Bit position of the image code in :attr:`jp_p` (27 for the half-stencil list).
    perm_n : (N,) int64 or None
        With ``sort``: sorted row k is particle ``perm_n[k]``.
    row_n : (N,) int64 or None
        With ``sort``: the inverse, particle i is sorted row ``row_n[i]``.
    offs_nc : (N, 3) float64
        Wrap offsets of the particles at the last build (caller's order; the array
        behind :attr:`offset_nc`; with ``sort`` a buffer kept across builds).
    xs_nc : (N, 3) float64
        With ``sort``: a buffer of sorted positions (wrapped positions at the
        build; the Cluster Dynamics calculator gathers each step's into it).
    offset_nc : (N, 3) float64
        Wrap of each particle into the box at the last build (caller's order).
    image_sc : (S, 3) float64
        Cartesian lattice translations indexed by the image codes.
    nbuilds : int
        Number of builds so far.
    version : int
        Builds and compactions (:meth:`remove`) so far: the list's arrays change with it.
    nremovals : int
        Compactions so far.
    layer_rows : int
        With ``sort``: the most rows in one layer of cells across the slowest
        cell axis at the last build (rows beyond it, a layer on, are the
        farthest a row's partners sit in a half list); 0 otherwise.
    last_cells : str
        "dense", "sparse" or "coarse" (the unsorted or full-stencil search on a
        grid coarsened to at most :data:`MAX_CELLS_PER_PARTICLE` cells per particle).
    """

    def __init__(self, cutoff, skin=0.0, half=True, sort=False, centered=False, cells="auto"):
        if not (float(cutoff) > 0):
            raise InputError("cutoff", cutoff, "a positive distance")
        if not (float(skin) >= 0):
            raise InputError("skin", skin, "a distance >= 0")
        if cells not in ("auto", "dense", "sparse"):
            raise InputError("cells", cells, "'auto', 'dense' or 'sparse'")
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.half = bool(half)
        self.sort = bool(sort)
        self.centered = bool(centered)
        self.cells = cells
        self.nbuilds = 0
        self.version = 0                # builds and compactions (remove)
        self.nremovals = 0
        self.compacted = False          # removals since the last build (see remove)
        self.ref_nc = None
        self._ref_store = None          # buffers behind ref_nc and the sorted rows' arrays (grow only)
        self._store = None
        self._key_store = None
        self.perm_n = None
        self.row_n = None
        self.layer_rows = 0
        self.jp_p = None
        self.img_shift = 0
        self.xs_nc = None
        self.offs_nc = None
        self.last_cells = None
        self._j_p = None
        self._img_p = None
        self._key = None
        self._pool = np.empty(0, np.uint32)
        self._slab_need = None
        self._slab_rows = None
        self._ppr = (8.0, 8.0)          # pairs per row at the last build: mean, largest of a block
        self._bricks = None             # the local rebuild test (centered lists): see _set_bricks
        self._brick_store = None
        self._brick_side = 0.0
        self.nlocal = 0                 # rebuilds the local test saved
        self._disp = np.zeros((DISP_BLOCKS, 7))

    def update(self, positions, cell, pbc, displacement=None):
        """Rebuild if needed; return True when rebuilt.

        ``displacement``: (``max |x - ref|^2``, squared half-diagonal) of the
        current positions against :attr:`ref_nc`, when the caller already has
        them (:func:`kick_drift_gather`); saves the check's own pass.
        """
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        cell = np.asarray(cell, dtype=float).reshape(3, 3)
        pbc = np.asarray(pbc, dtype=bool)
        if pbc.shape != (3,):
            pbc = np.broadcast_to(pbc, (3,))
        use_threads(pos.shape[0])
        key = _box_key(cell, pbc)
        if (self.ref_nc is None or self.ref_nc.shape != pos.shape or key != self._key
                or (pos.shape[0] and self._moved(pos, displacement))):
            self.build(pos, cell, pbc)
            return True
        return False

    def _moved(self, pos, displacement=None):
        lim = (0.5 * self.skin) ** 2
        if displacement is not None:
            m, h2 = displacement
            if not self.centered:
                return not m <= lim
        elif not self.centered:
            m = _max_disp2(pos, self.ref_nc)
            return not m <= lim
        else:
            m, h2 = _displacement(pos, self.ref_nc, self._disp)
        if m <= lim or h2 <= lim:
            return False
        if self._bricks is not None and math.isfinite(m) and math.isfinite(h2):
            brick_n, blo, bhi, box, periodic_c, acc, mid, hi, acc2, rad, skey, sid, nb_c, csz = self._bricks
            _brick_centres(pos, self.ref_nc, brick_n, acc, hi, mid)
            _brick_radii(pos, self.ref_nc, brick_n, mid, acc2, rad)
            if _bricks_safe(mid, rad, blo, bhi, skey, sid, nb_c, csz, box, periodic_c, self.skin, self.cutoff,
                            MAX_BRICK_REACH):
                self.nlocal += 1
                return False
        return True

    def _grid(self, pos, cell, pbc):
        """Cells of side >= cutoff + skin over the box (periodic axes) and the bounding box (open
        ones): (lo, cell sizes, cell counts, stencil reach, periodic flags, periodic box, rcut)."""
        box_c, periodic_c = check_cell(cell, pbc)
        n = pos.shape[0]
        if not np.all(np.isfinite(pos)):
            bad = np.nonzero(~np.isfinite(pos).all(axis=1))[0]
            raise InputError("positions", f"non-finite at particles {bad[:5].tolist()}", "finite values")
        rcut = self.cutoff + self.skin
        lo = np.zeros(3)
        ext = np.zeros(3)
        for d in range(3):
            if periodic_c[d]:
                ext[d] = box_c[d]
            elif n:
                lo[d] = pos[:, d].min()
                ext[d] = pos[:, d].max() - lo[d]
        ncell = np.ones(3, np.int64)
        for d in range(3):
            ncell[d] = max(1, int(min(math.floor(ext[d] / rcut), 2 ** 62))) if ext[d] > 0 else 1
        return lo, ext, ncell, periodic_c, np.where(periodic_c, box_c, 0.0), rcut

    @staticmethod
    def _sizes(ext, ncell, periodic_c, rcut):
        """Cell sizes and stencil reach for the cell counts ``ncell``."""
        cs = np.ones(3)
        krange = np.ones(3, np.int64)
        for d in range(3):
            cs[d] = ext[d] / ncell[d] if ext[d] > 0 else rcut
            if not periodic_c[d]:
                cs[d] = max(cs[d], rcut)
            krange[d] = max(1, int(math.ceil(rcut / cs[d] - 1e-12)))
            if not periodic_c[d]:
                krange[d] = 1
        return cs, krange

    @staticmethod
    def _coarsen(ncell, limit):
        """Halve the largest cell count until the grid has at most ``limit`` cells (dilute,
        exploding samples on the dense and unsorted paths)."""
        ncell = ncell.copy()
        while float(np.prod(ncell.astype(float))) > limit:
            big = np.argmax(ncell)
            ncell[big] = max(1, ncell[big] // 2)
        return ncell

    def build(self, positions, cell, pbc):
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        geo = self._grid(pos, cell, pbc)
        if pos.shape[0] >= 2 ** 31:
            raise InputError("positions", f"{pos.shape[0]} particles", "fewer than 2**31 per list")
        if self.sort:
            self._build_sorted(pos, *geo)
        else:
            self._build_unsorted(pos, *geo)
        if self.centered:
            self._set_bricks(pos, geo)
        self._ref_store = grown(self._ref_store, pos.shape[0])
        self.ref_nc = self._ref_store[:pos.shape[0]]
        np.copyto(self.ref_nc, pos)
        self._key = _box_key(cell, pbc)
        self.nbuilds += 1
        self.version += 1
        self.compacted = False

    def _set_bricks(self, pos, geo):
        """The local rebuild test's bricks: cubes of at least :data:`BRICK_SIDE` (cutoff + skin)
        (along a periodic axis the box divided evenly), doubled until at most
        max(:data:`MAX_BRICKS`, N / :data:`PARTICLES_PER_BRICK`) are occupied.

        The global test (:meth:`_moved`) bounds every pair's change by the spread of all
        displacements; when it fails, the bricks bound it pair of bricks by pair of bricks,
        using how far apart the bricks were at the build (:func:`_bricks_safe`): an expanding
        cloud whose neighbourhoods move together keeps its list.  Brick of each particle: 4
        bytes; each brick about 100 bytes and 64 per thread.
        """
        lo, ext, ncell, periodic_c, box, rcut = geo
        n = pos.shape[0]
        self._bricks = None
        if n < 2:
            return
        side = BRICK_SIDE * rcut   # from the positions alone: a restart rebuilds the same bricks
        boxw = np.where(periodic_c, box, 1.0)
        maxb = max(MAX_BRICKS, n // PARTICLES_PER_BRICK)
        st = self._brick_store or (None,) * 4
        st = (grown(st[0], n, (), np.int32), grown(st[1], maxb), grown(st[2], maxb), grown(st[3], maxb, (), np.int64))
        self._brick_store = st
        brick_n, blo, bhi, bkey = st[0][:n], st[1], st[2], st[3]
        while True:
            nb_c = np.ones(3, np.int64)
            csz = np.empty(3)
            for d in range(3):
                if periodic_c[d]:
                    nb_c[d] = max(1, int(min(math.floor(box[d] / side), 2 ** 20)))
                    csz[d] = box[d] / nb_c[d]
                else:
                    nb_c[d] = max(1, int(min(math.floor(ext[d] / side), 2 ** 20)) + 1)
                    csz[d] = side
            if float(np.prod(nb_c.astype(float))) < 2.0 ** 62:
                m = _assign_bricks(pos, boxw, periodic_c, lo, csz, nb_c, maxb, brick_n, blo, bhi, bkey,
                                   self._keys(n))
                if m > 0:
                    break
            side *= 2.0
        self._brick_side = side
        if m < 2:
            return
        order = np.argsort(bkey[:m], kind="stable")
        nt = _brick_chunks()
        self._bricks = (brick_n, blo[:m], bhi[:m], box.astype(float), periodic_c,
                        np.empty((nt, m, 6)), np.empty((m, 3)), np.empty((m, 3)), np.empty((nt, m, 2)),
                        np.empty((m, 2)), bkey[:m][order], order.astype(np.int64), nb_c, csz)

    def _reserve_pool(self, size):
        """A pair pool of at least ``size`` entries (a build rewrites all of it).  When it must grow,
        the old pool and the list's view of it are let go first, so the two are never held together
        (they would add about 35 bytes a particle to the peak), and it grows by an eighth more than
        asked, so that a slowly densifying sample does not reallocate at every build."""
        if self._pool.shape[0] >= size:
            return
        self.jp_p = None
        self._pool = np.empty(0, np.uint32)
        self._pool = np.empty(size + size // 8, np.uint32)

    def _image_table(self, krange, box):
        kx, ky, kz = krange
        ii = np.arange(-kx, kx + 1)
        jj = np.arange(-ky, ky + 1)
        ll = np.arange(-kz, kz + 1)
        img = np.array(np.meshgrid(ii, jj, ll, indexing="ij")).reshape(3, -1).T
        return np.ascontiguousarray(img * box[None, :])

    def _count_and_fill(self, xs, cell_n, start, order, ncell, krange, periodic_c, box, rcut, first_n):
        """The full-stencil search in two passes: count each row's pairs into ``first_n`` (zeroed,
        (n + 1,)), turn the counts into row offsets, then fill the partner rows and image codes.

        Returns (j_p (P,) int32, img_p (P,) int16)."""
        _search(xs, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, True, first_n, np.empty(0, np.int32), np.empty(0, np.int16))
        np.cumsum(first_n, out=first_n)
        npairs = int(first_n[-1])
        j_p = np.empty(npairs, np.int32)
        img_p = np.empty(npairs, np.int16)
        _search(xs, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, False, first_n, j_p, img_p)
        return j_p, img_p

    def _build_unsorted(self, pos, lo, ext, ncell, periodic_c, box, rcut):
        n = pos.shape[0]
        ncell = self._coarsen(ncell, MAX_CELLS_PER_PARTICLE * max(n, 1) + 27)
        cs, krange = self._sizes(ext, ncell, periodic_c, rcut)
        wpos = np.empty_like(pos)
        _wrap(pos, np.where(periodic_c, box, 1.0), periodic_c, wpos)
        cell_n, start, order = _bin_particles(wpos, lo, 1.0 / cs, ncell)
        first_n = np.zeros(n + 1, np.int64)
        j_p, img_p = self._count_and_fill(wpos, cell_n, start, order, ncell, krange, periodic_c, box, rcut,
                                          first_n)
        self.image_sc = self._image_table(krange, box)
        self.first_n, self._j_p, self._img_p = first_n, j_p, img_p
        self.jp_p = None
        self.perm_n = None
        self.row_n = None
        self.layer_rows = 0
        self.offs_nc = wpos - pos
        self.last_cells = "coarse"

    def _keys(self, n):
        """Scratch of n int64 (the cell and brick keys of a build), kept across builds (grows only):
        allocating it per build fragments the heap (about 80 bytes per particle held after a few
        hundred builds)."""
        self._key_store = grown(self._key_store, n, (), np.int64)
        return self._key_store[:n]

    def _sorted_buffers(self, n):
        """The sorted rows' arrays for n particles: views of buffers kept across builds, which
        grow but never shrink, so that removing particles allocates nothing (every build writes
        every row of them)."""
        xs, offs, perm, first, row = self._store or (None,) * 5
        self._store = (grown(xs, n), grown(offs, n), grown(perm, n, (), np.int64), grown(first, n + 1, (), np.int64),
                       grown(row, n, (), np.int64))
        xs, offs, perm, first, row = self._store
        self.xs_nc, self.offs_nc, self.perm_n, self.first_n = xs[:n], offs[:n], perm[:n], first[:n + 1]
        self.row_n = row[:n]
        return self.perm_n, self.xs_nc, self.offs_nc, self.row_n

    def _build_sorted(self, pos, lo, ext, ncell, periodic_c, box, rcut):
        n = pos.shape[0]
        perm, xs, offs, row = self._sorted_buffers(n)
        boxw = np.where(periodic_c, box, 1.0)
        fast = self.half and all(ncell[d] >= 3 for d in range(3) if periodic_c[d])
        if fast:
            # keys of (k0 n1 + k1) n2 + k2 must fit in int64: for spreads beyond 2^62 cells the widest
            # axes get wider cells (a bounded key space, not a bounded memory: sparse memory is O(N))
            ncell = self._coarsen(ncell, 2.0 ** 62)
        cs, krange = self._sizes(ext, ncell, periodic_c, rcut)
        fast = fast and bool(np.all(krange == 1))
        # slowest-varying cell axis: the one with most cells (thinnest layers, so a
        # contiguous block of rows touches few rows outside itself)
        axes = np.array(sorted(range(3), key=lambda d: (-ncell[d], d)), np.int64)
        if not fast:
            self._build_sorted_search(pos, lo, ext, ncell, periodic_c, box, rcut, axes)
            return
        dense_cells = float(np.prod(ncell.astype(float)))
        sparse = (self.cells == "sparse"
                  or (self.cells == "auto" and dense_cells > DENSE_CELLS_PER_PARTICLE * max(n, 1) + 27))
        ukey, ustart, dstart = _sort_rows(pos, boxw, periodic_c, lo, 1.0 / cs, ncell, axes, perm, xs, offs, row,
                                          self._keys(n), sparse)
        if n >= 2 ** HALF_SHIFT:
            raise InputError("positions", f"{n} particles", f"fewer than 2**{HALF_SHIFT} in a sorted half list")
        nslot = ncell[axes]
        self.layer_rows = int(_layer_rows(ukey, ustart, nslot[1] * nslot[2]))
        periodic_s = periodic_c[axes].copy()
        slotbox = np.zeros((3, 3))
        for q, d in enumerate(axes):
            slotbox[q, d] = box[d]
        slotmult = np.array([9, 3, 1], np.int64)[axes]
        cblk, rows_b, maxrows = _cell_blocks(ustart, FILL_BLOCK_ROWS)
        need = self._slab_need
        first_n = self.first_n
        nblk = rows_b.shape[0]
        mean, top = self._ppr
        if need is not None and need.shape[0] == nblk:
            est = np.maximum((need * SLAB_MARGIN).astype(np.int64), (rows_b * mean).astype(np.int64))
        elif need is not None:
            est = _carried_need(need, self._slab_rows, rows_b, mean)
        else:
            est = (rows_b * (top * 1.1)).astype(np.int64)
        est += 64
        while True:
            slab = np.zeros(nblk + 1, np.int64)
            np.cumsum(est, out=slab[1:])
            self._reserve_pool(int(slab[-1]))
            need_b = np.empty(nblk, np.int64)
            _fill_slabs(xs, ukey, ustart, dstart, sparse, nslot, periodic_s, HALF_RUNS, slotbox, slotmult,
                        rcut * rcut, HALF_SHIFT, cblk, slab, maxrows, self._pool, first_n, need_b)
            if np.any(need_b > est):
                est = np.maximum(est, (need_b * SLAB_MARGIN).astype(np.int64) + 64)
            else:
                break
        self._slab_need = need_b
        self._slab_rows = rows_b
        self._ppr = (float(need_b.sum() / max(n, 1)), float((need_b / np.maximum(rows_b, 1)).max()))
        npairs = _close_slabs(self._pool, slab, need_b, first_n)
        self.jp_p = self._pool[:npairs]
        self.img_shift = HALF_SHIFT
        self._j_p = self._img_p = None
        self.image_sc = self._image_table(np.ones(3, np.int64), box)
        self.last_cells = "sparse" if sparse else "dense"

    def _build_sorted_search(self, pos, lo, ext, ncell, periodic_c, box, rcut, axes):
        """Sorted list by the full-stencil search (thin periodic boxes, full lists)."""
        n = pos.shape[0]
        perm, xs, offs, row = self._sorted_buffers(n)
        boxw = np.where(periodic_c, box, 1.0)
        ncell = self._coarsen(ncell, MAX_CELLS_PER_PARTICLE * max(n, 1) + 27)
        cs, krange = self._sizes(ext, ncell, periodic_c, rcut)
        axes = np.array(sorted(range(3), key=lambda d: (-ncell[d], d)), np.int64)
        ukey, ustart, _ = _sort_rows(pos, boxw, periodic_c, lo, 1.0 / cs, ncell, axes, perm, xs, offs, row,
                                     self._keys(n), False)
        self.layer_rows = int(_layer_rows(ukey, ustart, ncell[axes[1]] * ncell[axes[2]]))
        first_n = self.first_n
        first_n[:] = 0
        # _search decodes cells with x slowest: re-bin the sorted rows that way
        cell_x, start_x, order_x = _bin_particles(xs, lo, 1.0 / cs, ncell)
        j_p, img_p = self._count_and_fill(xs, cell_x, start_x, order_x, ncell, krange, periodic_c, box, rcut,
                                          first_n)
        npairs = j_p.shape[0]
        self.image_sc = self._image_table(krange, box)
        nimg = self.image_sc.shape[0]
        shift = 32 - max(1, int(nimg - 1).bit_length())
        if n > 2 ** shift:
            raise InputError("positions", f"{n} particles", f"at most 2**{shift} with {nimg} periodic images "
                             "(a box thinner than two cut-offs along a periodic axis)")
        self._reserve_pool(npairs)
        _pack(j_p, img_p, shift, self._pool)
        self.jp_p = self._pool[:npairs]
        self.img_shift = shift
        self._j_p, self._img_p = j_p, img_p
        self.last_cells = "coarse"

    @property
    def j_p(self):
        """(P,) int32 partner rows of the pairs."""
        if self._j_p is None and self.jp_p is not None:
            self._j_p = (self.jp_p & np.uint32((1 << self.img_shift) - 1)).astype(np.int32)
        return self._j_p

    @property
    def img_p(self):
        """(P,) int16 image codes of the pairs (rows of :attr:`image_sc`)."""
        if self._img_p is None and self.jp_p is not None:
            self._img_p = (self.jp_p >> np.uint32(self.img_shift)).astype(np.int16)
        return self._img_p

    @property
    def j_mask(self):
        """Mask of the partner row in :attr:`jp_p`."""
        return np.uint32((1 << self.img_shift) - 1)

    @property
    def offset_nc(self):
        """Wrap offsets at the last build, in the caller's particle order (a copy: a sorted
        list's buffer is rewritten by the next build)."""
        return self.offs_nc.copy()

    def renumber(self, scratch):
        """The caller has reordered its particles into the list's row order (new particle k is
        old particle ``perm_n[k]``).  The list stays valid without a rebuild: its rows, pairs and
        sorted arrays are untouched; the reference positions, the wrap offsets and the bricks of
        the local test follow, and the row permutation and its inverse become the identity.  ``scratch``: a
        :func:`clusterdyn.buffers.grown` buffer for :func:`clusterdyn.buffers.permute`."""
        if self.ref_nc is None or self.perm_n is None or self.ref_nc.shape[0] != self.perm_n.shape[0]:
            raise InputError("renumber", "a list not built over the current particles", "a built, sorted list")
        permute(self.ref_nc, self.perm_n, scratch)
        permute(self.offs_nc, self.perm_n, scratch)
        if self._bricks is not None:
            permute(self._bricks[0], self.perm_n, scratch)
        _identity(self.perm_n)
        _identity(self.row_n)

    @property
    def in_order(self):
        """True when the rows are in the caller's order (the permutation is the identity): after
        :meth:`renumber`, after a build that found them so, and through compactions of either.
        Read from the permutation (one pass, stopping at the first row out of place)."""
        return self.perm_n is not None and bool(_is_identity(self.perm_n))

    def remove(self, keep_n):
        """The caller drops the particles where ``keep_n`` is False (the others keeping their
        order, as ``atoms[keep_n]`` does).  A sorted list built over the current particles stays
        valid without a rebuild: the dropped rows and every pair with a dropped partner go, the
        kept rows keep their order and their pairs (:func:`_compact_rows`, one pass, in place:
        nothing of N's size is allocated); the reference positions, wrap offsets and the local
        test's bricks follow (emptied bricks are dropped, the others' build boxes are taken
        again over the particles kept).  Returns False, changing nothing, for a list that can
        not be compacted (unsorted, or not built over these particles): the caller rebuilds.
        :attr:`version` counts builds and compactions (what users of the list's arrays key on);
        rows in the caller's order (:attr:`in_order`) stay so.

        The compacted list holds the pairs a build from the kept reference positions would
        hold, but its rows are in the old build's order (a build sorts them over the kept
        particles' own bounding box), so pair sums add in another order: :attr:`compacted`
        says so until the next build (a checkpoint rebuilds from the reference positions
        first, as its restart does)."""
        keep = np.asarray(keep_n)
        if (self.perm_n is None or self.ref_nc is None or keep.dtype != np.bool_ or keep.ndim != 1
                or self.ref_nc.shape[0] != keep.shape[0] or self.perm_n.shape[0] != keep.shape[0]):
            return False
        n = keep.shape[0]
        br = self._bricks
        brick_n = br[0] if br is not None else np.zeros(0, np.int32)
        m, npairs = _compact_rows(keep, self.perm_n, self.row_n, self.first_n, self._pool, self.j_mask,
                                  self.xs_nc, self.offs_nc, self.ref_nc, brick_n, self._keys(n))
        self._sorted_buffers(m)
        self.ref_nc = self._ref_store[:m]
        self.jp_p = self._pool[:npairs]
        self._j_p = self._img_p = None
        self.layer_rows = max(1, self.layer_rows * m // max(n, 1)) if self.layer_rows else 0
        if br is not None:
            self._drop_bricks(m)
        self.version += 1
        self.nremovals += 1
        self.compacted = True
        return True

    def _drop_bricks(self, m):
        """The local test's bricks over the ``m`` particles kept by :meth:`remove`."""
        brick_n, blo, bhi, box, periodic_c, *_, skey, sid, nb_c, csz = self._bricks
        brick_n = self._brick_store[0][:m]
        newb = _renumber_bricks(brick_n, blo.shape[0])
        mb = int(newb.max()) + 1 if newb.size else 0
        if mb < 2:
            self._bricks = None
            return
        nt = _brick_chunks()
        blo, bhi = self._brick_store[1][:mb], self._brick_store[2][:mb]
        _brick_boxes(self.ref_nc, np.where(periodic_c, box, 1.0), periodic_c, brick_n, np.empty((nt, mb, 6)),
                     blo, bhi)
        u = newb[sid] >= 0
        self._bricks = (brick_n, blo, bhi, box, periodic_c, np.empty((nt, mb, 6)), np.empty((mb, 3)),
                        np.empty((mb, 3)), np.empty((nt, mb, 2)), np.empty((mb, 2)), skey[u].copy(),
                        newb[sid[u]].astype(np.int64), nb_c, csz)

    def scratch(self, n):
        """A scratch of ``n`` rows of :data:`~clusterdyn.buffers.PERMUTE_WORDS` float64 words for
        :func:`clusterdyn.buffers.permute` (and :meth:`renumber`) between builds: the builds' key
        scratch, whose contents matter only inside a build, so a caller's sort of its particles
        holds no memory of its own.  Valid until the next build."""
        return self._keys(n * PERMUTE_WORDS).view(np.float64).reshape(n, PERMUTE_WORDS)

    @property
    def npairs(self):
        return int(self.first_n[-1])

    def memory_bytes(self):
        """Bytes of the arrays the list keeps between builds (list, permutation, buffers)."""
        arrs = [self._ref_store, self._pool, self._j_p, self._img_p, self._disp]
        arrs += list(self._store) if self._store is not None else [self.first_n, self.offs_nc]
        arrs.append(self._key_store)
        if self._bricks is not None:          # the brick store's arrays, and those made per build
            arrs += list(self._brick_store)
            arrs += [a for a in self._bricks[3:] if isinstance(a, np.ndarray)]
        return int(sum(a.nbytes for a in arrs if a is not None))

    def sorted_positions(self, positions, out=None):
        """Wrapped positions in the list's row order (sorted lists), Angstrom."""
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        if self.perm_n is None:
            return pos + self.offs_nc
        if out is None:
            out = np.empty_like(pos)
        gather_positions(pos, self.perm_n, self.offs_nc, out)
        return out

    def pairs(self, positions):
        """Python-side view: (i_p, j_p, d_pc, r_p) for the given positions (tests, analysis).

        Indices are the caller's particle rows, also for a sorted list.
        """
        pos = np.asarray(positions, dtype=float)
        i_p = np.repeat(np.arange(len(pos)), np.diff(self.first_n))
        j_p = self.j_p.astype(np.int64)
        w = self.sorted_positions(pos)
        d = w[j_p] - w[i_p] + self.image_sc[self.img_p]
        if self.perm_n is not None:
            i_p = self.perm_n[i_p]
            j_p = self.perm_n[j_p]
        return i_p, j_p, d, np.sqrt((d * d).sum(axis=1))

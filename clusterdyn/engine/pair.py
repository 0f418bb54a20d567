"""numba kernels of the Cluster Dynamics pair loop.

Every kernel walks a half Verlet list over particles held in cell order
(``clusterdyn.neighbors.NeighborList(sort=True)``: row k is particle
``perm_n[k]``) in fixed chunks of rows.  Chunk k accumulates into its own
buffer rows, which cover only the rows its pairs touch (``span_k2[k]``: its
own rows plus the few cell layers ahead of them), and :func:`~clusterdyn.engine.chunks.reduce_rows`
sums the buffers of a row in chunk order and scatters the sum to the
caller's row ``perm_n[i]``.  The chunks depend on the particle count only,
not on the thread count, so forces are bit-identical on any number of
threads, and no two threads write one row.

Arguments: four tuples of arrays, whose fields the namedtuples :class:`PairArgs` (the list and
the particles), :class:`Tables`, :class:`PassBuffers` and :class:`Finish` (and
:class:`~clusterdyn.engine.chunks.Chunks`) name, plus a :class:`Variant` of compile-time flags.
The kernels take them as plain tuples in that field order and unpack them by position: numba
types a namedtuple argument in Python (about 0.4 us a field, 12 us a pass) but a plain tuple in
C.  Specialisation: one loop body (:func:`_chunk`), inlined into small module-level kernels
(cached on disk by numba), one per :class:`Variant` constant (:data:`KERNELS`; :func:`select`
picks one from what a pass asks); LLVM removes the code of every term a variant does not use.

- ``MULTI``: more than one material (type lookups per pair); else the
  single table ``[0, 0]`` is read with its constants hoisted out of the loop.
- ``DAMP``: pair damping of CD eq. (6) fused into the loop.
- ``VIR``: the cell virial (for ``stress``).
- ``PP``: per-particle energies and virials (``energies``, ``stresses``).
- ``attraction="initial"``: a run-time flag (``PairArgs.initial``) of the
  multi-material kernels, which also serve single-material runs that use it.
- ``CONS``: a damped pass that also keeps the conservative forces apart, in buffer rows of their
  own (``c_mc``), summed in the same order as the undamped kernels sum theirs: the same bits as
  a conservative pass gives (:class:`clusterdyn.md.DampedVerlet` asks for them on the steps an
  observer reads, so that an H5MD frame of a damped run needs no pass of its own).
- ``ENERGY``: the pair energy (the dynamics' steps leave it out, about a
  tenth of the loop; :class:`clusterdyn.md.DampedVerlet` asks for it in a step's
  pass only when an observer reads that step, else when it is read).
- ``FIN``: the step kernels (forces only, damped or not) also write the
  force of every row no other chunk touches to ``out_nc[perm_n[i]]``, with
  the half kick ``p_nc += h f`` when ``p_nc`` is not empty, right after the
  chunk's loop (its buffer rows are still in cache); :func:`~clusterdyn.engine.chunks.reduce_shared`
  then sums only the shared rows, often few enough for one thread.  The sum
  of a row with one term is that term, so the forces are the same bits as
  :func:`~clusterdyn.engine.chunks.reduce_rows` gives.
- ``TRACK``: the rows of the closest pair (the single-material steps keep
  only its distance; the calculator reruns a tracking variant when the pair
  is asked for, which with one material is only to name it in an error).

The periodic image shift is added only to pairs that cross a periodic face
(image code other than the middle of ``image_sc``).

Table layout (potentials.build_tables): ``coef[a, b, k, 0:4]`` cubic
coefficients of the shifted pair energy in bin k of a grid uniform in
``s = r^2``; ``meta[a, b]`` = (s_min, 1/h_s, cutoff^2, r_min^2 (= s_min),
1/r0_ab^2, E(cutoff), r0_ab^2).  The pair force is ``-2 dE/ds`` times the
separation vector: no square root or division in the loop.  Its quadratic in
the bin (:func:`table_force`) is two explicit fused multiply-adds: exactly
rounded, so the forces are the same bits on every CPU.

``attraction="initial"`` (docs/theory.md 1.5): a pair not listed in ``bonds_nk``
(partner ids bonded at set-up, -1 padded, one row per particle, caller's
order) only repels: zero force beyond r0_ab and energy ``E(r) - E(r0_ab)``
inside, so it stays conservative.

Outputs per chunk: ``stat_k[k]`` = (energy, smallest r^2/r0_ab^2, its row i,
its row j (-1 when not tracked), number of pairs closer than the table, the power the pair
damping dissipates ``sum eta |v_i - v_j|^2`` (``DAMP`` variants; 0 otherwise)), ``vir_k6[k]`` =
pair virial (xx yy zz yz xz xy), eV.
"""

from collections import namedtuple

import numpy as np
from numba import njit, prange

from ..fma import fma
from .chunks import _put3


#: the list and the particles of a pass (rows in the list's order; ``type_s``: material ids of
#: the rows, empty for one material; ``bonds_nk``, ``id_n``: set-up bonds and stable ids in the
#: caller's order, read when ``initial``, the ``attraction="initial"`` rule)
PairArgs = namedtuple("PairArgs", "xs_nc type_s first_n jp_p shift image_sc perm_n bonds_nk id_n initial")


#: the pair tables (:func:`kernel_tables`) and the damping matrix (empty without damping)
Tables = namedtuple("Tables", "gtab coef meta eta_tt")


#: a pass's buffers: the chunks' force rows, their stats and virials, the rows' velocities (empty
#: without damping), the per-particle rows (empty unless asked) and the conservative force rows
#: of a damped pass (``CONS``; empty otherwise)
PassBuffers = namedtuple("PassBuffers", "f_mc stat_k vir_k6 vs_nc e_m1 w_m6 c_mc")


#: where a pass's forces go: ``out_nc`` (caller's order) and the half kick ``p_nc += h f``
#: (``p_nc`` empty: none)
Finish = namedtuple("Finish", "out_nc p_nc h")


#: the compile-time flags of a pass (module docstring); one kernel per value (:data:`KERNELS`)
Variant = namedtuple("Variant", "MULTI DAMP VIR PP ENERGY TRACK FIN CONS", defaults=(False,))


def kernel_tables(coef, meta):
    """The tables the kernels read: ``(coef, gtab)``, both (nt, nt, nb + 1, 4) float64.

    ``coef`` is the energy cubic of :func:`clusterdyn.potentials.build_tables`;
    ``gtab[..., k, :]`` = (-2 c1/h_s, -4 c2/h_s, -6 c3/h_s, 1): the pair force
    over the separation, ``-2 dE/ds = g0 + t (g1 + t g2)``, with the constants
    folded in (two multiplications fewer per pair), and 1 marking a bin within
    the cut-off (the damping's weight).  Bin ``nb`` is zero in both: a pair
    beyond its cut-off (in the list's skin) lands there and adds nothing, so
    the step kernels need no branch per pair.
    """
    nt, _, nb, _ = coef.shape
    c = np.zeros((nt, nt, nb + 1, 4))
    c[:, :, :nb] = coef
    g = np.zeros((nt, nt, nb + 1, 4))
    invh = meta[:, :, 1][:, :, None]
    g[:, :, :nb, 0] = -2.0 * invh * coef[..., 1]
    g[:, :, :nb, 1] = -4.0 * invh * coef[..., 2]
    g[:, :, :nb, 2] = -6.0 * invh * coef[..., 3]
    g[:, :, :nb, 3] = 1.0
    return c, g


@njit(inline="always")
def table_force(gtab, a, b, kbu, t):
    """The pair force over the separation, ``-2 dE/ds``, in bin ``kbu`` at ``t``:
    ``g0 + t (g1 + t g2)`` as two fused multiply-adds (one rounding each: shorter than a
    multiplication and an addition on the loop's critical path, and within 1e-16 of them)."""
    return fma(t, fma(t, gtab[a, b, kbu, 2], gtab[a, b, kbu, 1]), gtab[a, b, kbu, 0])


@njit(inline="always")
def _bonded(bonds_nk, i, jid):
    for k in range(bonds_nk.shape[1]):
        b = bonds_nk[i, k]
        if b == jid:
            return True
        if b < 0:
            return False
    return False


@njit(inline="always")
def _chunk(k, args, tab, ch, V, vs_nc, f_mc, stat_k, vir_k6, e_m1, w_m6, c_mc, out_nc, p_nc, h):
    """The pair loop of chunk k: ``args`` :class:`PairArgs`, ``tab`` :class:`Tables`, ``ch``
    :class:`~clusterdyn.engine.chunks.Chunks` (read only, as plain tuples in the namedtuples'
    field order), ``V`` the :class:`Variant` (a module constant of the calling kernel: its flags
    fold away); the fields of :class:`PassBuffers` and :class:`Finish` one by one (:func:`_pass`)."""
    MULTI, DAMP, VIR, PP, ENERGY, TRACK, FIN = V.MULTI, V.DAMP, V.VIR, V.PP, V.ENERGY, V.TRACK, V.FIN
    CONS = V.CONS
    xs_nc, type_s, first_n, jp_p, shift, image_sc, perm_n, bonds_nk, id_n, initial = args
    INIT = initial if MULTI else False
    gtab, coef, meta, eta_tt = tab
    bounds_k, span_k2, boff_k, _, _, shared_n, _, _ = ch
    off = boff_k[k] - span_k2[k, 0]
    offu = np.uint64(off)
    zero_img = np.uint32(image_sc.shape[0] // 2)
    sh = np.uint32(shift)
    jmask = np.uint32((1 << shift) - 1)
    for r in range(boff_k[k], boff_k[k + 1]):
        f_mc[r, 0] = 0.0
        f_mc[r, 1] = 0.0
        f_mc[r, 2] = 0.0
        if CONS:
            c_mc[r, 0] = 0.0
            c_mc[r, 1] = 0.0
            c_mc[r, 2] = 0.0
        if PP:
            e_m1[r, 0] = 0.0
            for c in range(6):
                w_m6[r, c] = 0.0
    nbu = np.uint64(coef.shape[2] - 1)   # the last bin is zero: pairs beyond the cut-off land there
    a = 0
    b = 0
    smin = meta[0, 0, 0]
    invh = meta[0, 0, 1]
    cut2 = meta[0, 0, 2]
    rmin2 = meta[0, 0, 3]
    eta = 0.0
    if DAMP:
        eta = eta_tt[0, 0]
    energy = 0.0
    vxx = 0.0
    vyy = 0.0
    vzz = 0.0
    vyz = 0.0
    vxz = 0.0
    vxy = 0.0
    minr2 = 1e300
    ci = -1
    cj = -1
    nclose = 0
    dissip = 0.0
    for i in range(bounds_k[k], bounds_k[k + 1]):
        if MULTI:
            a = type_s[i]
        xi = xs_nc[i, 0]
        yi = xs_nc[i, 1]
        zi = xs_nc[i, 2]
        vxi = 0.0
        vyi = 0.0
        vzi = 0.0
        if DAMP:
            vxi = vs_nc[i, 0]
            vyi = vs_nc[i, 1]
            vzi = vs_nc[i, 2]
        fxi = 0.0
        fyi = 0.0
        fzi = 0.0
        cxi = 0.0
        cyi = 0.0
        czi = 0.0
        for p in range(np.uint64(first_n[i]), np.uint64(first_n[i + 1])):
            v = jp_p[p]
            ju = np.uint64(v & jmask)  # unsigned: no negative-index wraparound code per access
            dx = xs_nc[ju, 0] - xi
            dy = xs_nc[ju, 1] - yi
            dz = xs_nc[ju, 2] - zi
            s = v >> sh
            if s != zero_img:
                su = np.uint64(s)
                dx += image_sc[su, 0]
                dy += image_sc[su, 1]
                dz += image_sc[su, 2]
            r2 = dx * dx + dy * dy + dz * dz
            if MULTI:
                b = type_s[ju]
                cut2 = meta[a, b, 2]
                rmin2 = meta[a, b, 3]
                smin = meta[a, b, 0]
                invh = meta[a, b, 1]
            r2n = r2
            if MULTI:
                r2n = r2 * meta[a, b, 4]
            if TRACK:
                # the energy, virial and per-particle passes: pairs beyond the cut-off skipped,
                # the closest pair and the pairs below the table counted
                if not r2 < cut2:
                    continue
                if r2n < minr2:
                    minr2 = r2n
                    ci = i
                    cj = np.int64(ju)
                if r2 < rmin2:
                    nclose += 1
                    continue
            else:
                # the steps: no branch per pair; a pair beyond its cut-off evaluates the zero
                # bin; the smallest distance over all listed pairs (beyond the cut-off only
                # when no pair is within it, which the calculator reports as inf)
                minr2 = min(minr2, r2n)
                if MULTI:
                    nclose += 1 if r2 < rmin2 else 0
            free = False
            if INIT:
                free = not _bonded(bonds_nk, perm_n[i], id_n[perm_n[ju]])
                if free and r2 >= meta[a, b, 6]:
                    continue
            x = (r2 - smin) * invh
            kb = int(x)
            t = x - kb
            # one unsigned clamp: a bin past the last (a pair in the skin) or below the first (a
            # pair closer than the table, x < 0, which every variant reports and the calculator
            # raises on) reads the zero bin
            kbu = min(np.uint64(kb), nbu)
            s_ = table_force(gtab, a, b, kbu, t)
            e = 0.0
            if ENERGY:  # (every per-particle variant has it)
                c1 = coef[a, b, kbu, 1]
                c2 = coef[a, b, kbu, 2]
                c3 = coef[a, b, kbu, 3]
                e = coef[a, b, kbu, 0] + t * (c1 + t * (c2 + t * c3))
                if INIT:
                    if free:
                        e += meta[a, b, 5]
                energy += e
            fx = s_ * dx
            fy = s_ * dy
            fz = s_ * dz
            if VIR or PP:
                hxx = -fx * dx
                hyy = -fy * dy
                hzz = -fz * dz
                hyz = -fy * dz
                hxz = -fx * dz
                hxy = -fx * dy
                vxx += hxx
                vyy += hyy
                vzz += hzz
                vyz += hyz
                vxz += hxz
                vxy += hxy
                if PP:
                    ri = off + i
                    rj = offu + ju
                    e_m1[ri, 0] += 0.5 * e
                    e_m1[rj, 0] += 0.5 * e
                    w_m6[ri, 0] += 0.5 * hxx
                    w_m6[ri, 1] += 0.5 * hyy
                    w_m6[ri, 2] += 0.5 * hzz
                    w_m6[ri, 3] += 0.5 * hyz
                    w_m6[ri, 4] += 0.5 * hxz
                    w_m6[ri, 5] += 0.5 * hxy
                    w_m6[rj, 0] += 0.5 * hxx
                    w_m6[rj, 1] += 0.5 * hyy
                    w_m6[rj, 2] += 0.5 * hzz
                    w_m6[rj, 3] += 0.5 * hyz
                    w_m6[rj, 4] += 0.5 * hxz
                    w_m6[rj, 5] += 0.5 * hxy
            if CONS:
                # the conservative force alone, summed as the undamped kernels sum theirs
                cxi -= fx
                cyi -= fy
                czi -= fz
                rj = offu + ju
                c_mc[rj, 0] += fx
                c_mc[rj, 1] += fy
                c_mc[rj, 2] += fz
            if DAMP:
                if MULTI:
                    eta = eta_tt[a, b]
                ein = eta * gtab[a, b, kbu, 3]          # 1 within the cut-off, 0 beyond
                dvx = vxi - vs_nc[ju, 0]
                dvy = vyi - vs_nc[ju, 1]
                dvz = vzi - vs_nc[ju, 2]
                fx += ein * dvx
                fy += ein * dvy
                fz += ein * dvz
                dissip += ein * (dvx * dvx + dvy * dvy + dvz * dvz)
            fxi -= fx
            fyi -= fy
            fzi -= fz
            rj = offu + ju
            f_mc[rj, 0] += fx
            f_mc[rj, 1] += fy
            f_mc[rj, 2] += fz
        f_mc[off + i, 0] += fxi
        f_mc[off + i, 1] += fyi
        f_mc[off + i, 2] += fzi
        if CONS:
            c_mc[off + i, 0] += cxi
            c_mc[off + i, 1] += cyi
            c_mc[off + i, 2] += czi
    if FIN:
        kick = p_nc.shape[0] > 0
        for i in range(bounds_k[k], bounds_k[k + 1]):
            if shared_n[i] == 0:
                r = off + i
                _put3(out_nc, p_nc, np.uint64(perm_n[i]), f_mc[r, 0], f_mc[r, 1], f_mc[r, 2], kick, h)
    if not MULTI:
        minr2 *= meta[0, 0, 4]
    if not TRACK and not MULTI:
        nclose = -1               # not counted: the calculator recounts when minr2 is below the table
    stat_k[k, 0] = energy
    stat_k[k, 1] = minr2
    stat_k[k, 2] = ci
    stat_k[k, 3] = cj
    stat_k[k, 4] = nclose
    stat_k[k, 5] = dissip
    vir_k6[k, 0] = vxx
    vir_k6[k, 1] = vyy
    vir_k6[k, 2] = vzz
    vir_k6[k, 3] = vyz
    vir_k6[k, 4] = vxz
    vir_k6[k, 5] = vxy



@njit(inline="always")
def _pass(args, tab, ch, buf, fin, V):
    """Every chunk's loop, in parallel (the body of the kernels below).  The arrays a chunk
    writes are taken out of their tuples here, outside the ``prange`` loop: numba loses the
    writes to an array taken out of a tuple inside it (numba 0.58)."""
    f_mc, stat_k, vir_k6, vs_nc, e_m1, w_m6, c_mc = buf
    out_nc, p_nc, h = fin
    for k in prange(ch[0].shape[0] - 1):
        _chunk(k, args, tab, ch, V, vs_nc, f_mc, stat_k, vir_k6, e_m1, w_m6, c_mc, out_nc, p_nc, h)


# -- the variants: one module-level kernel per Variant constant (cached on disk by numba) ----

V_FORCES_1 = Variant(MULTI=False, DAMP=False, VIR=False, PP=False, ENERGY=False, TRACK=False, FIN=True)
V_FORCES_ENERGY_1 = Variant(MULTI=False, DAMP=False, VIR=False, PP=False, ENERGY=True, TRACK=False, FIN=True)
V_VIRIAL_1 = Variant(MULTI=False, DAMP=False, VIR=True, PP=False, ENERGY=True, TRACK=True, FIN=False)
V_DAMPED_1 = Variant(MULTI=False, DAMP=True, VIR=False, PP=False, ENERGY=False, TRACK=False, FIN=True)
V_DAMPED_ENERGY_1 = Variant(MULTI=False, DAMP=True, VIR=False, PP=False, ENERGY=True, TRACK=False, FIN=True)
V_DAMPED_CONS_1 = Variant(MULTI=False, DAMP=True, VIR=False, PP=False, ENERGY=True, TRACK=False, FIN=True,
                          CONS=True)
V_PER_PARTICLE_1 = Variant(MULTI=False, DAMP=False, VIR=True, PP=True, ENERGY=True, TRACK=True, FIN=False)
V_FORCES_MULTI = Variant(MULTI=True, DAMP=False, VIR=False, PP=False, ENERGY=False, TRACK=True, FIN=True)
V_FORCES_ENERGY_MULTI = Variant(MULTI=True, DAMP=False, VIR=False, PP=False, ENERGY=True, TRACK=True, FIN=True)
V_VIRIAL_MULTI = Variant(MULTI=True, DAMP=False, VIR=True, PP=False, ENERGY=True, TRACK=True, FIN=False)
V_DAMPED_MULTI = Variant(MULTI=True, DAMP=True, VIR=False, PP=False, ENERGY=False, TRACK=True, FIN=True)
V_DAMPED_ENERGY_MULTI = Variant(MULTI=True, DAMP=True, VIR=False, PP=False, ENERGY=True, TRACK=True, FIN=True)
V_DAMPED_CONS_MULTI = Variant(MULTI=True, DAMP=True, VIR=False, PP=False, ENERGY=True, TRACK=True, FIN=True,
                              CONS=True)
V_PER_PARTICLE_MULTI = Variant(MULTI=True, DAMP=False, VIR=True, PP=True, ENERGY=True, TRACK=True, FIN=False)


@njit(cache=True, parallel=True)
def pass_forces_1(args, tab, ch, buf, fin):
    """One material: forces only (the dynamics' undamped step)."""
    _pass(args, tab, ch, buf, fin, V_FORCES_1)


@njit(cache=True, parallel=True)
def pass_forces_energy_1(args, tab, ch, buf, fin):
    """One material: forces and energy (an undamped step whose energy is read)."""
    _pass(args, tab, ch, buf, fin, V_FORCES_ENERGY_1)


@njit(cache=True, parallel=True)
def pass_virial_1(args, tab, ch, buf, fin):
    """One material: forces, energy and cell virial."""
    _pass(args, tab, ch, buf, fin, V_VIRIAL_1)


@njit(cache=True, parallel=True)
def pass_damped_1(args, tab, ch, buf, fin):
    """One material: conservative + pair damping forces (velocities ``vs_nc`` in row order)."""
    _pass(args, tab, ch, buf, fin, V_DAMPED_1)


@njit(cache=True, parallel=True)
def pass_damped_energy_1(args, tab, ch, buf, fin):
    """One material: damped forces and the (conservative) energy."""
    _pass(args, tab, ch, buf, fin, V_DAMPED_ENERGY_1)


@njit(cache=True, parallel=True)
def pass_damped_cons_1(args, tab, ch, buf, fin):
    """One material: damped forces, the energy, and the conservative forces apart (``c_mc``)."""
    _pass(args, tab, ch, buf, fin, V_DAMPED_CONS_1)


@njit(cache=True, parallel=True)
def pass_per_particle_1(args, tab, ch, buf, fin):
    """One material: forces, energy, virial and per-particle energies and virials."""
    _pass(args, tab, ch, buf, fin, V_PER_PARTICLE_1)


@njit(cache=True, parallel=True)
def pass_forces_multi(args, tab, ch, buf, fin):
    """Several materials (or attraction='initial'): forces only."""
    _pass(args, tab, ch, buf, fin, V_FORCES_MULTI)


@njit(cache=True, parallel=True)
def pass_forces_energy_multi(args, tab, ch, buf, fin):
    """Several materials: forces and energy."""
    _pass(args, tab, ch, buf, fin, V_FORCES_ENERGY_MULTI)


@njit(cache=True, parallel=True)
def pass_virial_multi(args, tab, ch, buf, fin):
    """Several materials: forces, energy and cell virial."""
    _pass(args, tab, ch, buf, fin, V_VIRIAL_MULTI)


@njit(cache=True, parallel=True)
def pass_damped_multi(args, tab, ch, buf, fin):
    """Several materials: conservative + pair damping forces."""
    _pass(args, tab, ch, buf, fin, V_DAMPED_MULTI)


@njit(cache=True, parallel=True)
def pass_damped_energy_multi(args, tab, ch, buf, fin):
    """Several materials: damped forces and the energy."""
    _pass(args, tab, ch, buf, fin, V_DAMPED_ENERGY_MULTI)


@njit(cache=True, parallel=True)
def pass_damped_cons_multi(args, tab, ch, buf, fin):
    """Several materials: damped forces, the energy, and the conservative forces apart."""
    _pass(args, tab, ch, buf, fin, V_DAMPED_CONS_MULTI)


@njit(cache=True, parallel=True)
def pass_per_particle_multi(args, tab, ch, buf, fin):
    """Several materials: with per-particle energies and virials."""
    _pass(args, tab, ch, buf, fin, V_PER_PARTICLE_MULTI)


#: the kernel of each variant
KERNELS = {
    V_FORCES_1: pass_forces_1,
    V_FORCES_ENERGY_1: pass_forces_energy_1,
    V_VIRIAL_1: pass_virial_1,
    V_DAMPED_1: pass_damped_1,
    V_DAMPED_ENERGY_1: pass_damped_energy_1,
    V_DAMPED_CONS_1: pass_damped_cons_1,
    V_PER_PARTICLE_1: pass_per_particle_1,
    V_FORCES_MULTI: pass_forces_multi,
    V_FORCES_ENERGY_MULTI: pass_forces_energy_multi,
    V_VIRIAL_MULTI: pass_virial_multi,
    V_DAMPED_MULTI: pass_damped_multi,
    V_DAMPED_ENERGY_MULTI: pass_damped_energy_multi,
    V_DAMPED_CONS_MULTI: pass_damped_cons_multi,
    V_PER_PARTICLE_MULTI: pass_per_particle_multi,
}


def select(multi, *, damped, per_particle, virial, energy, step, conservative=False):
    """The variant of a pass: several materials (or ``attraction="initial"``) or one; damped;
    per-particle energies and virials; the cell virial; the energy; ``step``: a dynamics step's
    pass (forces with the half kick); ``conservative``: a damped pass that also keeps the
    conservative forces apart (with the energy).  A pass without virial or per-particle output,
    damped or a step, writes its unshared rows itself (``FIN``)."""
    if damped and conservative:
        return V_DAMPED_CONS_MULTI if multi else V_DAMPED_CONS_1
    if damped:
        return V_DAMPED_ENERGY_MULTI if multi and energy else V_DAMPED_MULTI if multi else \
            V_DAMPED_ENERGY_1 if energy else V_DAMPED_1
    if per_particle:
        return V_PER_PARTICLE_MULTI if multi else V_PER_PARTICLE_1
    if step and not virial:
        return V_FORCES_ENERGY_MULTI if multi and energy else V_FORCES_MULTI if multi else \
            V_FORCES_ENERGY_1 if energy else V_FORCES_1
    if virial or energy:
        return V_VIRIAL_MULTI if multi else V_VIRIAL_1
    return V_FORCES_MULTI if multi else V_FORCES_1


def run(variant, args, tab, ch, buf, fin):
    """Run the pass of ``variant`` over every chunk (the arguments as plain tuples, see
    :data:`PairArgs`)."""
    KERNELS[variant](args, tab, ch, buf, fin)




@njit(cache=True)
def pairs_touching(args, tab, mask_n, vs_nc, f_nc):
    """What the listed pairs with at least one particle in ``mask_n`` (caller's order) contribute:
    returns (energy, dissipation), and subtracts their forces from ``f_nc`` (caller's order;
    skipped when it is empty).  The energy as the energy passes count it (pairs within the cut-off
    and the table; with ``init``, the ``attraction="initial"`` rule): what the potential energy
    loses when those particles are taken out.  The forces and the dissipation as the step kernels
    make them, with the pair damping when ``vs_nc`` (sorted rows' velocities, those of the force
    pass that made ``f_nc``) is not empty: ``f_nc`` minus them is that pass's forces without the
    pairs.  ``args.type_s``: material ids in the caller's order (not the rows'), or empty (one
    material).  One thread, rows and pairs in list order: the same bits on any thread count."""
    xs_nc, types_n, first_n, jp_p, shift, image_sc, perm_n, bonds_nk, id_n, init = args
    gtab, coef, meta, eta_tt = tab
    n = first_n.shape[0] - 1
    nbu = np.uint64(coef.shape[2] - 1)
    zero_img = np.uint32(image_sc.shape[0] // 2)
    sh = np.uint32(shift)
    jmask = np.uint32((1 << shift) - 1)
    multi = types_n.shape[0] > 0
    damp = vs_nc.shape[0] > 0
    forces = f_nc.shape[0] > 0
    energy = 0.0
    dissip = 0.0
    for i in range(n):
        pi = perm_n[i]
        gi = mask_n[pi]
        a = types_n[pi] if multi else 0
        for p in range(first_n[i], first_n[i + 1]):
            v = jp_p[p]
            j = np.int64(v & jmask)
            pj = perm_n[j]
            if not (gi or mask_n[pj]):
                continue
            dx = xs_nc[j, 0] - xs_nc[i, 0]
            dy = xs_nc[j, 1] - xs_nc[i, 1]
            dz = xs_nc[j, 2] - xs_nc[i, 2]
            s = v >> sh
            if s != zero_img:
                dx += image_sc[s, 0]
                dy += image_sc[s, 1]
                dz += image_sc[s, 2]
            r2 = dx * dx + dy * dy + dz * dz
            b = types_n[pj] if multi else 0
            free = False
            if init:
                free = not _bonded(bonds_nk, pi, id_n[pj])
                if free and r2 >= meta[a, b, 6]:
                    continue
            x = (r2 - meta[a, b, 0]) * meta[a, b, 1]
            kb = int(x)
            t = x - kb
            kbu = min(np.uint64(kb), nbu)
            if r2 < meta[a, b, 2] and not r2 < meta[a, b, 3]:
                e = coef[a, b, kbu, 0] + t * (coef[a, b, kbu, 1] + t * (coef[a, b, kbu, 2] + t * coef[a, b, kbu, 3]))
                if free:
                    e += meta[a, b, 5]
                energy += e
            s_ = table_force(gtab, a, b, kbu, t)
            fx = s_ * dx
            fy = s_ * dy
            fz = s_ * dz
            if damp:
                ein = eta_tt[a, b] * gtab[a, b, kbu, 3]
                dvx = vs_nc[i, 0] - vs_nc[j, 0]
                dvy = vs_nc[i, 1] - vs_nc[j, 1]
                dvz = vs_nc[i, 2] - vs_nc[j, 2]
                fx += ein * dvx
                fy += ein * dvy
                fz += ein * dvz
                dissip += ein * (dvx * dvx + dvy * dvy + dvz * dvz)
            if forces:
                f_nc[pi, 0] += fx
                f_nc[pi, 1] += fy
                f_nc[pi, 2] += fz
                f_nc[pj, 0] -= fx
                f_nc[pj, 1] -= fy
                f_nc[pj, 2] -= fz
    return energy, dissip

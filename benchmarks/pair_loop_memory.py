"""How much of the undamped pair loop waits on memory, and what the step kernel adds to the loop.

    python benchmarks/pair_loop_memory.py            # -> results/pair_loop_memory.{md,json}

On the list and positions of the 128k piston shock with 30% of the sample shocked
(``benchmarks/_states.py``; one thread, process clock), this script times the step's
undamped kernel (``cd_forces_1``) and copies of its pair loop, all compiled here the same
way, called in turn ``--repeat`` times; each variant's time is given against the loop
alone as the median of the ratios of calls made one after the other (the host's load
moves both alike):

- ``loop alone``: the kernel's pair loop into the chunk's buffer rows, without the pass
  that writes the rows no other chunk touches to the caller's arrays (with the half kick);
- ``loop, partners in L1``: the same instructions with every partner index taken modulo
  1024 (its positions and buffer rows, 24 KB each, stay in the level-1 cache; the forces
  are wrong, the work per pair is the same: the loop has no branch per pair but the
  periodic image's);
- ``loop + prefetch, partner + d``: a software prefetch (``llvm.prefetch``) of the
  position row d rows after each partner's;
- ``loop + prefetch, row's last partner + d``: one prefetch of the position row and one of
  the buffer row d rows after the row's last partner (the farthest run of the stencil);
- ``loop + finishing pass``: the kernel's work, the loop then its pass over the chunk's
  rows (checked: the same bits as the kernel);
- ``loop + finishing every 2048 rows``: that pass in blocks, each over the rows no later
  row of the chunk can write (the chunk's largest backward reach of a pair, measured on
  the list), while their buffer rows are closer in the cache;
- ``loop + finishing each row``: the same, one row at a time inside the row loop;
- ``loop, image pairs last in each row (no test)``: each row's pairs across a periodic face
  moved to its end (a stable reorder; 5% of the pairs, in 13% of the rows), the others in a
  loop without the image test;
- ``loop, table of 3 columns``: the table without the column of ones that only the damped
  kernels read (250 KB instead of 333 KB, against the level-2 cache's 512 KB);
- ``loop, float32 table``: the table's coefficients in single precision (the force error
  against the loop is printed);
- ``kernel, Atoms in cell order``: the kernel with the identity permutation (the caller's
  rows written in sequence, as they would be if the Atoms were held in cell order).

The loop variants' buffer rows are compared with the loop's (force error column); the
finishing variants' caller rows and momenta with the kernel's (same bits).
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from llvmlite import ir
from numba import njit, prange
from numba.core import cgutils, types
from numba.extending import intrinsic

from clusterdyn.calculators._cd_kernels import _put3, table_force

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _states import write_report  # noqa: E402
from gather_pair_loop import capture  # noqa: E402
RESULTS = HERE / "results"


def _prefetcher(write):
    """An intrinsic ``f(arr, idx)``: ``llvm.prefetch`` of row ``idx`` of a 2-D array, for a read
    (``write`` 0) or a write (1), kept in every cache level."""
    @intrinsic
    def prefetch(typingctx, arr, idx):
        sig = types.void(arr, types.uint64)

        def codegen(context, builder, signature, args):
            a, i = args
            aty = signature.args[0]
            ary = context.make_array(aty)(context, builder, a)
            ptr = cgutils.get_item_pointer(context, builder, aty, ary, [i, context.get_constant(types.intp, 0)])
            i8p = ir.IntType(8).as_pointer()
            i32 = ir.IntType(32)
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                                "llvm.prefetch.p0i8")
            builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, write), ir.Constant(i32, 3),
                              ir.Constant(i32, 1)])
            return context.get_dummy_value()
        return sig, codegen
    return prefetch


_prefetch_read = _prefetcher(0)
_prefetch_write = _prefetcher(1)


#: the loop's variants
PLAIN, IN_L1, PF_PAIR, PF_ROW, FIN_END, FIN_BLOCK, FIN_ROW, IMG_LAST = range(8)


@njit(inline="always")
def _sep(xs_nc, ju, xi, yi, zi):
    return xs_nc[ju, 0] - xi, xs_nc[ju, 1] - yi, xs_nc[ju, 2] - zi


@njit(inline="always")
def _force(dx, dy, dz, gtab, smin, invh, nbu):
    """The kernel's work for one pair from its separation: the force vector and r^2."""
    r2 = dx * dx + dy * dy + dz * dz
    x = (r2 - smin) * invh
    kb = int(x)
    t = x - kb
    kbu = min(np.uint64(kb), nbu)
    s_ = table_force(gtab, 0, 0, kbu, t)
    return s_ * dx, s_ * dy, s_ * dz, r2


@njit(inline="always")
def _take(f_mc, r, fx, fy, fz, r2, minr2, fxi, fyi, fzi):
    """A pair's force added to its partner's buffer row; returns the row's updated smallest r^2
    and force sum (the kernel's order of operations)."""
    f_mc[r, 0] += fx
    f_mc[r, 1] += fy
    f_mc[r, 2] += fz
    return min(minr2, r2), fxi - fx, fyi - fy, fzi - fz


def make(mode, dist=0):
    @njit(inline="always")
    def finish(q0, q1, off, shared_n, perm_n, f_mc, out_nc, p_nc, h):
        for q in range(q0, q1):
            if shared_n[q] == 0:
                r = off + q
                _put3(out_nc, p_nc, np.uint64(perm_n[q]), f_mc[r, 0], f_mc[r, 1], f_mc[r, 2], True, h)

    @njit(parallel=True)
    def loop(xs_nc, first_n, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k, f_mc, stat_k,
             shared_n, out_nc, p_nc, h, perm_n, lag_k, mid_n):
        for k in prange(bounds_k.shape[0] - 1):
            off = boff_k[k] - span_k2[k, 0]
            offu = np.uint64(off)
            zero_img = np.uint32(image_sc.shape[0] // 2)
            sh = np.uint32(shift)
            jfull = np.uint32((1 << shift) - 1)
            jmask = np.uint32(1023) if mode == IN_L1 else jfull
            for r in range(boff_k[k], boff_k[k + 1]):
                f_mc[r, 0] = 0.0
                f_mc[r, 1] = 0.0
                f_mc[r, 2] = 0.0
            nbu = np.uint64(gtab.shape[2] - 1)
            smin = meta[0, 0, 0]
            invh = meta[0, 0, 1]
            minr2 = 1e300
            nlast = np.uint64(xs_nc.shape[0] - 1)
            flast = np.uint64(f_mc.shape[0] - 1)
            done = bounds_k[k]
            for i in range(bounds_k[k], bounds_k[k + 1]):
                xi = xs_nc[i, 0]
                yi = xs_nc[i, 1]
                zi = xs_nc[i, 2]
                fxi = 0.0
                fyi = 0.0
                fzi = 0.0
                p0 = np.uint64(first_n[i])
                p1 = np.uint64(first_n[i + 1])
                if mode == PF_ROW and p1 > p0:
                    jl = np.uint64(jp_p[p1 - np.uint64(1)] & jfull)
                    _prefetch_read(xs_nc, min(jl + np.uint64(dist), nlast))
                    _prefetch_write(f_mc, min(offu + jl + np.uint64(dist), flast))
                if mode == IMG_LAST:
                    # the row's pairs across a periodic face last: no image test per pair
                    pm = np.uint64(mid_n[i])
                    for p in range(p0, pm):
                        ju = np.uint64(jp_p[p] & jmask)
                        dx, dy, dz = _sep(xs_nc, ju, xi, yi, zi)
                        fx, fy, fz, r2 = _force(dx, dy, dz, gtab, smin, invh, nbu)
                        minr2, fxi, fyi, fzi = _take(f_mc, offu + ju, fx, fy, fz, r2, minr2, fxi, fyi, fzi)
                    for p in range(pm, p1):
                        v = jp_p[p]
                        ju = np.uint64(v & jmask)
                        su = np.uint64(v >> sh)
                        dx, dy, dz = _sep(xs_nc, ju, xi, yi, zi)
                        fx, fy, fz, r2 = _force(dx + image_sc[su, 0], dy + image_sc[su, 1], dz + image_sc[su, 2],
                                                gtab, smin, invh, nbu)
                        minr2, fxi, fyi, fzi = _take(f_mc, offu + ju, fx, fy, fz, r2, minr2, fxi, fyi, fzi)
                    p1 = p0
                for p in range(p0, p1):
                    v = jp_p[p]
                    ju = np.uint64(v & jmask)
                    if mode == PF_PAIR:
                        _prefetch_read(xs_nc, min(ju + np.uint64(dist), nlast))
                    dx, dy, dz = _sep(xs_nc, ju, xi, yi, zi)
                    s = v >> sh
                    if s != zero_img:
                        su = np.uint64(s)
                        dx += image_sc[su, 0]
                        dy += image_sc[su, 1]
                        dz += image_sc[su, 2]
                    fx, fy, fz, r2 = _force(dx, dy, dz, gtab, smin, invh, nbu)
                    minr2, fxi, fyi, fzi = _take(f_mc, offu + ju, fx, fy, fz, r2, minr2, fxi, fyi, fzi)
                f_mc[off + i, 0] += fxi
                f_mc[off + i, 1] += fyi
                f_mc[off + i, 2] += fzi
                if mode == FIN_BLOCK and (i - bounds_k[k]) % 2048 == 2047:
                    upto = max(done, i + 1 - lag_k[k])
                    finish(done, upto, off, shared_n, perm_n, f_mc, out_nc, p_nc, h)
                    done = upto
                if mode == FIN_ROW:
                    q = i - lag_k[k]
                    if q >= bounds_k[k]:
                        finish(q, q + 1, off, shared_n, perm_n, f_mc, out_nc, p_nc, h)
            if mode == FIN_END or mode == FIN_BLOCK:
                finish(done, bounds_k[k + 1], off, shared_n, perm_n, f_mc, out_nc, p_nc, h)
            if mode == FIN_ROW:
                finish(max(bounds_k[k + 1] - lag_k[k], bounds_k[k]), bounds_k[k + 1], off, shared_n, perm_n, f_mc,
                       out_nc, p_nc, h)
            stat_k[k, 1] = minr2
    return loop


def backward_reach(first_n, jp_p, shift, bounds_k):
    """Per chunk, one more than the largest ``i - j`` of a pair (i, j) with j < i within the
    chunk (pairs across a periodic face of the layer): row q is final once row q + reach is done."""
    n = first_n.shape[0] - 1
    row = np.repeat(np.arange(n), np.diff(first_n))
    j = (jp_p & np.uint32((1 << shift) - 1)).astype(np.int64)
    lag = np.ones(bounds_k.shape[0] - 1, np.int64)
    for k in range(lag.shape[0]):
        a0, a1 = first_n[bounds_k[k]], first_n[bounds_k[k + 1]]
        back = (j[a0:a1] < row[a0:a1]) & (j[a0:a1] >= bounds_k[k])
        if back.any():
            lag[k] = int((row[a0:a1][back] - j[a0:a1][back]).max()) + 1
    return lag


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=25)
    ap.add_argument("--out", default=str(RESULTS / "pair_loop_memory"))
    a = ap.parse_args(argv)
    from clusterdyn.parallel import set_max_threads
    import clusterdyn.calculators._cd_kernels as K
    set_max_threads(1)
    args = capture()
    (xs, _, first_n, jp_p, shift, image_sc, gtab, _, meta, bounds_k, span_k2, boff_k, f_mc, stat_k, *_rest) = args
    shared_n, out_nc, p_nc, h = args[23:27]
    perm = args[19]
    p0 = p_nc.copy()
    n = xs.shape[0]
    lag = backward_reach(first_n, jp_p, shift, bounds_k)

    # the list with each row's pairs across a periodic face moved last (stable), and where they start
    img = (jp_p >> np.uint32(shift)) != image_sc.shape[0] // 2
    row = np.repeat(np.arange(n), np.diff(first_n))
    jp_last = jp_p[np.lexsort((img, row))]
    mid = first_n[:-1] + np.bincount(row[~img], minlength=n)

    def loop_call(fn, out, p, jp=jp_p, tab=gtab):
        return fn, (xs, first_n, jp, shift, image_sc, tab, meta, bounds_k, span_k2, boff_k, f_mc.copy(),
                    stat_k.copy(), shared_n, out, p, h, perm, lag, mid)

    variants = {}
    ko, kp = out_nc.copy(), p0.copy()
    kargs = list(args)
    kargs[12], kargs[13], kargs[24], kargs[25] = f_mc.copy(), stat_k.copy(), ko, kp
    variants["kernel (cd_forces_1)"] = (K.cd_forces_1, tuple(kargs), ko, kp)
    for name, mode, d in (("loop alone", PLAIN, 0), ("loop, partners in L1", IN_L1, 0),
                          ("loop + prefetch, partner + 8", PF_PAIR, 8), ("loop + prefetch, partner + 16", PF_PAIR, 16),
                          ("loop + prefetch, partner + 32", PF_PAIR, 32),
                          ("loop + prefetch, row's last partner + 8", PF_ROW, 8),
                          ("loop + prefetch, row's last partner + 16", PF_ROW, 16),
                          ("loop + finishing pass", FIN_END, 0), ("loop + finishing every 2048 rows", FIN_BLOCK, 0),
                          ("loop + finishing each row", FIN_ROW, 0)):
        o, q = out_nc.copy(), p0.copy()
        variants[name] = (*loop_call(make(mode, d), o, q), o, q)
    for name, kw in (("loop, image pairs last in each row (no test)", {"jp": jp_last}),
                     ("loop, table of 3 columns (24 bytes a bin)", {"tab": np.ascontiguousarray(gtab[..., :3])}),
                     ("loop, float32 table", {"tab": gtab.astype(np.float32)})):
        o, q = out_nc.copy(), p0.copy()
        variants[name] = (*loop_call(make(IMG_LAST if "image" in name else PLAIN), o, q, **kw), o, q)
    io, ip = out_nc.copy(), p0.copy()
    iargs = list(kargs)
    iargs[12], iargs[13], iargs[24], iargs[25] = f_mc.copy(), stat_k.copy(), io, ip
    iargs[19] = np.arange(n, dtype=perm.dtype)
    variants["kernel, Atoms in cell order"] = (K.cd_forces_1, tuple(iargs), io, ip)

    for fn, fa, o, q in variants.values():      # compile, then one call each from the same momenta
        fn(*fa)
        np.copyto(q, p0)
        fn(*fa)
    ref_o, ref_p = variants["kernel (cd_forces_1)"][2:]
    same = {}
    for name in ("loop + finishing pass", "loop + finishing every 2048 rows", "loop + finishing each row"):
        o, q = variants[name][2:]
        same[name] = bool(np.array_equal(o, ref_o) and np.array_equal(q, ref_p))
    fbuf = {name: v[1][10] for name, v in variants.items() if v[0] is not K.cd_forces_1}
    ref_buf = fbuf["loop alone"]
    err = {name: float(np.abs(b - ref_buf).max() / np.abs(ref_buf).max()) for name, b in fbuf.items()
           if "L1" not in name}
    times = {name: [] for name in variants}
    for rep in range(a.repeat):
        for name, (fn, fa, _, _) in variants.items():
            t0 = time.process_time()
            fn(*fa)
            times[name].append(time.process_time() - t0)
    base = np.array(times["loop alone"])
    kern = np.array(times["kernel (cd_forces_1)"])
    rows = []
    for name, ts in times.items():
        ts = np.array(ts)
        rows.append({"variant": name, "ns_per_particle": 1e9 * float(np.median(ts)) / n,
                     "vs_loop": float(np.median(ts / base)), "vs_kernel": float(np.median(ts / kern)),
                     "same_bits_as_kernel": same.get(name), "force_error_vs_loop": err.get(name)})
        print(f"{name:42s} {rows[-1]['ns_per_particle']:6.1f} ns/particle  x{rows[-1]['vs_loop']:.3f} loop"
              f"  x{rows[-1]['vs_kernel']:.3f} kernel", flush=True)
    meta_ = {"N": n, "pairs_per_particle": jp_p.shape[0] / n, "repeat": a.repeat, "backward_reach": lag.tolist(),
             "consecutive_caller_rows": float(np.mean(np.diff(perm) == 1)),
             "date": time.strftime("%Y-%m-%d %H:%M"), "load": os.getloadavg()[0]}
    L = ["# The undamped pair loop: memory, prefetch and the finishing pass", "",
         f"{meta_['date']}: `python benchmarks/pair_loop_memory.py --repeat {a.repeat}`; 128k piston shock, 30% "
         f"shocked, N = {n}, {meta_['pairs_per_particle']:.2f} listed pairs a particle, one thread, process clock; "
         f"ratios are medians of calls made one after the other; load average {meta_['load']:.1f}.  Chunks' "
         f"backward reach (rows): {', '.join(map(str, lag))}; caller rows in sequence in the cell order: "
         f"{meta_['consecutive_caller_rows']:.0%}.", "",
         "| variant | ns / particle | x loop alone | x kernel | same bits as the kernel | force error against "
         "the loop |", "|---|---:|---:|---:|---|---:|"]
    for r in rows:
        sb = "" if r["same_bits_as_kernel"] is None else ("yes" if r["same_bits_as_kernel"] else "no")
        fe = "" if r["force_error_vs_loop"] is None else f"{r['force_error_vs_loop']:.1e}"
        L.append(f"| {r['variant']} | {r['ns_per_particle']:.1f} | {r['vs_loop']:.3f} | {r['vs_kernel']:.3f} | "
                 f"{sb} | {fe} |")
    print(f"wrote {write_report(a.out, {'meta': meta_, 'rows': rows}, L)}")


if __name__ == "__main__":
    main()

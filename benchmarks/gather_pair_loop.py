"""Would a vectorised pair loop pay on this CPU?  The undamped kernel against two-pass variants.

    python benchmarks/gather_pair_loop.py            # -> results/gather_pair_loop.{md,json}

The pair loop of the undamped step (``cd_forces_1``) is scalar: the partner stores
``f[j] += ...`` and the per-row sums keep LLVM from vectorising it.  This script
times, on the list and positions of the 128k piston shock with 30% of the sample
shocked (``benchmarks/_states.py``; one thread, process clock, median of
``--repeat`` calls), the kernel against two-pass variants of the same work:

- pass A, one flat loop over the pairs of a block of rows (``--block`` rows): the
  separation (``x[j] - x[i]`` plus the periodic image, always added), r^2, the
  table's bin and the force vector, written to per-pair buffers; the bin's minimum
  instead of the smallest r^2 (a floating-point min reduction keeps LLVM from
  vectorising);
- pass B, scalar, in the kernel's order: each row's sum and the partner stores.

``two-pass, scalar``: the buffers are views of a per-chunk array, which numba's
parallel alias analysis counts as aliases, so the chunk loop is compiled without
``noalias`` and LLVM leaves pass A scalar.  ``two-pass, gathers``: the same code
with flat buffers; numba marks the arrays ``noalias`` and LLVM vectorises pass A
with AVX-512 (or AVX2) gathers (the script counts the ``masked.gather`` calls in
the IR).  Both give the kernel's forces bit for bit (checked).  ``float32
inputs``: the kernel compiled for float32 positions and tables (accumulators and
constants stay float64); its force error against float64 is printed.  ``pass A
alone``: the two-pass variants without pass B (no forces: what the vectorised part
costs by itself).
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit, prange

from clusterdyn.calculators._cd_kernels import _put3, table_force

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _states import write_report  # noqa: E402
RESULTS = HERE / "results"


@njit(inline="always")
def _two_pass_chunk(k, xs_nc, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k,
                    f_mc, stat_k, shared_n, out_nc, p_nc, h, fx_q, fy_q, fz_q, base, block, pass_b):
    off = boff_k[k] - span_k2[k, 0]
    offu = np.uint64(off)
    sh = np.uint32(shift)
    jmask = np.uint32((1 << shift) - 1)
    for r in range(boff_k[k], boff_k[k + 1]):
        f_mc[r, 0] = 0.0
        f_mc[r, 1] = 0.0
        f_mc[r, 2] = 0.0
    nb = gtab.shape[2] - 1
    smin = meta[0, 0, 0]
    invh = meta[0, 0, 1]
    kbmin = nb
    i0 = bounds_k[k]
    i1 = bounds_k[k + 1]
    for ia in range(i0, i1, block):
        ib = min(ia + block, i1)
        pa = np.uint64(first_n[ia])
        pb = np.uint64(first_n[ib])
        for p in range(pa, pb):                       # pass A: flat over the block's pairs
            i = np.uint64(pi_p[p])
            v = jp_p[p]
            ju = np.uint64(v & jmask)
            su = np.uint64(v >> sh)
            dx = xs_nc[ju, 0] - xs_nc[i, 0] + image_sc[su, 0]
            dy = xs_nc[ju, 1] - xs_nc[i, 1] + image_sc[su, 1]
            dz = xs_nc[ju, 2] - xs_nc[i, 2] + image_sc[su, 2]
            r2 = dx * dx + dy * dy + dz * dz
            x = (r2 - smin) * invh
            kb = min(max(np.int64(x), 0), nb)
            kbmin = min(kbmin, kb)
            t = x - kb
            kbu = np.uint64(kb)
            s_ = table_force(gtab, 0, 0, kbu, t)
            q = p - pa + base
            fx_q[q] = s_ * dx
            fy_q[q] = s_ * dy
            fz_q[q] = s_ * dz
        for i in range(ia, ib if pass_b else ia):     # pass B: the kernel's sums, in its order
            fxi = 0.0
            fyi = 0.0
            fzi = 0.0
            for p in range(np.uint64(first_n[i]), np.uint64(first_n[i + 1])):
                q = p - pa + base
                fx = fx_q[q]
                fy = fy_q[q]
                fz = fz_q[q]
                fxi -= fx
                fyi -= fy
                fzi -= fz
                rj = offu + np.uint64(jp_p[p] & jmask)
                f_mc[rj, 0] += fx
                f_mc[rj, 1] += fy
                f_mc[rj, 2] += fz
            f_mc[off + i, 0] += fxi
            f_mc[off + i, 1] += fyi
            f_mc[off + i, 2] += fzi
    kick = p_nc.shape[0] > 0
    for i in range(i0, i1):
        if shared_n[i] == 0:
            r = off + i
            _put3(out_nc, p_nc, np.uint64(i), f_mc[r, 0], f_mc[r, 1], f_mc[r, 2], kick, h)
    stat_k[k, 1] = kbmin


@njit(parallel=True)
def two_pass_views(xs_nc, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k,
                   f_mc, stat_k, shared_n, out_nc, p_nc, h, fx_kq, fy_kq, fz_kq, block, pass_b):
    """Per-chunk buffer rows as views (aliases to numba: compiled without noalias, pass A scalar)."""
    for k in prange(bounds_k.shape[0] - 1):
        _two_pass_chunk(k, xs_nc, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k,
                        f_mc, stat_k, shared_n, out_nc, p_nc, h, fx_kq[k], fy_kq[k], fz_kq[k], np.uint64(0),
                        block, pass_b)


@njit(parallel=True)
def two_pass_flat(xs_nc, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k,
                  f_mc, stat_k, shared_n, out_nc, p_nc, h, fx_q, fy_q, fz_q, per_chunk, block, pass_b):
    """Flat buffers, chunk k at ``k * per_chunk`` (no aliases: noalias, pass A vectorised)."""
    for k in prange(bounds_k.shape[0] - 1):
        _two_pass_chunk(k, xs_nc, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k,
                        f_mc, stat_k, shared_n, out_nc, p_nc, h, fx_q, fy_q, fz_q, np.uint64(k * per_chunk),
                        block, pass_b)


def capture():
    """The undamped kernel's arguments on the 128k 30%-shocked state (copies)."""
    import clusterdyn.calculators._cd_kernels as K
    from _states import load_state, shock_state
    cap = {}
    orig = K.KERNELS[False, "forces"]

    def grab(*a):
        cap["args"] = tuple(x.copy() if isinstance(x, np.ndarray) else x for x in a)
        return orig(*a)
    K.KERNELS[False, "forces"] = grab
    try:
        atoms, dyn, _ = load_state(shock_state(128, 0.3), J=None)
        dyn.run(3)
    finally:
        K.KERNELS[False, "forces"] = orig
    return list(cap["args"])


def gathers_in(fn):
    ir = fn.overloads[fn.signatures[0]].library.get_llvm_str()
    return ir.count("masked.gather")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--block", type=int, default=1024, help="rows per pass-A block")
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--out", default=str(RESULTS / "gather_pair_loop"))
    a = ap.parse_args(argv)
    import clusterdyn.calculators._cd_kernels as K
    from clusterdyn.parallel import set_max_threads
    set_max_threads(1)
    args = capture()
    (xs, _, first_n, jp_p, shift, image_sc, gtab, _, meta, bounds_k, span_k2, boff_k, f_mc, stat_k, *_rest) = args
    n = xs.shape[0]
    perm = args[19]
    args[19] = np.arange(n, dtype=perm.dtype)        # every variant writes rows in sorted order
    shared_n, out_nc, p_nc, h = args[23], args[24], args[25], args[26]
    p0 = p_nc.copy()
    pi_p = np.repeat(np.arange(n, dtype=np.uint32), np.diff(first_n).astype(np.int64))
    nk = bounds_k.shape[0] - 1
    per_chunk = int(max(first_n[bounds_k[k + 1]] - first_n[bounds_k[k]] for k in range(nk)))

    def fresh():
        return f_mc.copy(), stat_k.copy(), out_nc.copy(), p0.copy()

    variants = {}
    f1, s1, o1, q1 = fresh()
    kargs = list(args)
    kargs[12], kargs[13], kargs[24], kargs[25] = f1, s1, o1, q1
    variants["kernel (scalar, one pass)"] = (K.cd_forces_1, tuple(kargs), o1, q1)
    f2, s2, o2, q2 = fresh()
    bufv = [np.zeros((nk, per_chunk)) for _ in range(3)]
    variants["two-pass, scalar"] = (two_pass_views, (xs, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k,
                                                     span_k2, boff_k, f2, s2, shared_n, o2, q2, h, *bufv, a.block,
                                                     True), o2, q2)
    f3, s3, o3, q3 = fresh()
    buff = [np.zeros(nk * per_chunk) for _ in range(3)]
    variants["two-pass, gathers"] = (two_pass_flat, (xs, first_n, pi_p, jp_p, shift, image_sc, gtab, meta, bounds_k,
                                                     span_k2, boff_k, f3, s3, shared_n, o3, q3, h, *buff, per_chunk,
                                                     a.block, True), o3, q3)
    f5, s5, o5, q5 = fresh()
    variants["pass A alone, scalar"] = (two_pass_views, (xs, first_n, pi_p, jp_p, shift, image_sc, gtab, meta,
                                                         bounds_k, span_k2, boff_k, f5, s5, shared_n, o5, q5, h,
                                                         *bufv, a.block, False), o5, q5)
    f6, s6, o6, q6 = fresh()
    variants["pass A alone, gathers"] = (two_pass_flat, (xs, first_n, pi_p, jp_p, shift, image_sc, gtab, meta,
                                                         bounds_k, span_k2, boff_k, f6, s6, shared_n, o6, q6, h,
                                                         *buff, per_chunk, a.block, False), o6, q6)
    f4, s4, o4, q4 = fresh()
    a32 = list(args)
    a32[0] = xs.astype(np.float32)
    a32[5] = image_sc.astype(np.float32)
    a32[6] = gtab.astype(np.float32)
    a32[8] = meta.astype(np.float32)
    a32[12], a32[13], a32[24], a32[25] = f4.astype(np.float32), s4, o4, q4
    variants["float32 inputs"] = (K.cd_forces_1, tuple(a32), o4, q4)

    for fn, fa, _, q in variants.values():      # compile, then one call from the same momenta
        fn(*fa)
    for fn, fa, _, q in variants.values():
        np.copyto(q, p0)
        fn(*fa)
    ref = variants["kernel (scalar, one pass)"][2]
    fmax = np.abs(ref).max()
    rows = []
    times = {name: [] for name in variants}
    for _ in range(a.repeat):
        for name, (fn, fa, _, _) in variants.items():
            t0 = time.process_time()
            fn(*fa)
            times[name].append(time.process_time() - t0)
    gat = {"two-pass, scalar": gathers_in(two_pass_views), "two-pass, gathers": gathers_in(two_pass_flat)}
    gat["pass A alone, scalar"] = gat["two-pass, scalar"]
    gat["pass A alone, gathers"] = gat["two-pass, gathers"]
    base = np.median(times["kernel (scalar, one pass)"])
    for name, (fn, fa, out, _) in variants.items():
        t = float(np.median(times[name]))
        err = float(np.abs(out - ref).max() / fmax) if "alone" not in name else float("nan")
        rows.append({"variant": name, "ns_per_particle": 1e9 * t / n, "ns_per_pair": 1e9 * t / jp_p.shape[0],
                     "relative": t / base, "force_error": err,
                     "identical": bool(np.array_equal(out, ref)) if "alone" not in name else None,
                     "gathers_in_ir": gat.get(name, 0)})
        print(f"{name:28s} {1e9 * t / n:6.1f} ns/particle  x{t / base:4.2f}  force error {err:.1e}"
              f"  gathers in IR {gat.get(name, 0)}", flush=True)
    meta_ = {"N": n, "pairs_per_particle": jp_p.shape[0] / n, "block": a.block, "repeat": a.repeat,
             "date": time.strftime("%Y-%m-%d %H:%M"),
             "load": os.getloadavg()[0]}
    L = ["# A vectorised pair loop against the scalar kernel", "",
         f"{meta_['date']}: `python benchmarks/gather_pair_loop.py --block {a.block} --repeat {a.repeat}`; "
         f"128k piston shock, 30% shocked, N = {n}, {meta_['pairs_per_particle']:.2f} listed pairs a particle, "
         f"one thread, process clock, median of the calls; load average {meta_['load']:.1f}.", "",
         "| variant | ns / particle | ns / listed pair | x kernel | force error | same bits | gathers in IR |",
         "|---|---:|---:|---:|---:|---|---:|"]
    for r in rows:
        err, same = ("n/a", "n/a") if r["identical"] is None else (f"{r['force_error']:.1e}",
                                                                  "yes" if r["identical"] else "no")
        L.append(f"| {r['variant']} | {r['ns_per_particle']:.1f} | {r['ns_per_pair']:.2f} | {r['relative']:.2f} | "
                 f"{err} | {same} | {r['gathers_in_ir']} |")
    print(f"wrote {write_report(a.out, {'meta': meta_, 'rows': rows}, L)}")


if __name__ == "__main__":
    main()

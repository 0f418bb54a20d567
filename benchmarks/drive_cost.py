"""What the drives cost in DampedVerlet's fast path: the 32k-cluster shock with and without a wall.

    python benchmarks/drive_cost.py --nx 32 --rounds 8 --steps 20 --threads 1

One process, the aluminium piston shock (``build_shock``, cross-section 16 x
16 cells, N = 1024 nx), in variants that differ only by their drives:

- ``piston``: the scene as it is (a constant piston);
- ``piston U(t)``: the piston's velocity as a two-point Table (same run);
- ``+ wall, free``: plus a Wall at the rear face, just beyond its reach (every
  step pays the wall's pass over all particles, no particle touched);
- ``+ wall, touching``: plus a Wall whose reach covers the rear face's
  particles (the pass, the forces and the extra half kick on those rows).

After ``--warmup`` steps, rounds of ``--steps`` steps run each variant in
turn; printed: the median over rounds of the wall time per particle and
step (ns) and the median of each round's difference from ``piston`` (the
machine's load drifts between rounds, less within one).  Then the drives'
own per-step work timed alone on the same samples (their constraint hooks
for one step, repeated ``--calls`` times): the part of the difference that
is theirs, free of the run's noise.
"""

import argparse
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nx", type=int, default=32, help="sample length in cells (N = 1024 nx)")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=30)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--calls", type=int, default=300)
    a = ap.parse_args(argv)

    from clusterdyn import units
    from clusterdyn.md import DampedVerlet, Piston, Table, Wall
    from clusterdyn.parallel import set_max_threads
    from clusterdyn.scenes.shock import build_shock

    set_max_threads(a.threads)

    def variant(kind):
        s = build_shock(size=(a.nx, 16, 16), u=3 * units.km_s)
        r0 = s.calc.potentials[0].r0
        x_max = s.atoms.positions[:, 0].max()
        cons = [s.piston]
        if kind == "piston U(t)":
            cons = [Piston(s.piston.index, Table([0.0, 1.0 * units.s], [3 * units.km_s] * 2))]
        elif kind == "+ wall, free":
            cons.append(Wall([x_max + 0.6 * r0, 0, 0], [-1.0, 0.0, 0.0]))
        elif kind == "+ wall, touching":
            cons.append(Wall([x_max + 0.45 * r0, 0, 0], [-1.0, 0.0, 0.0]))
        s.atoms.set_constraint(cons)
        dyn = DampedVerlet(s.atoms, timestep=s.dyn.dt, J=None)
        dyn.run(a.warmup)
        return s, dyn, cons

    kinds = ["piston", "piston U(t)", "+ wall, free", "+ wall, touching"]
    runs = {k: variant(k) for k in kinds}
    n = len(runs["piston"][0].atoms)
    touched = runs["+ wall, touching"][2][1]._nt
    times = {k: [] for k in kinds}
    for _ in range(a.rounds):
        for k in kinds:
            dyn = runs[k][1]
            t0 = time.perf_counter()
            dyn.run(a.steps)
            times[k].append((time.perf_counter() - t0) / (n * a.steps) * 1e9)
    base = np.array(times["piston"])
    print(f"N = {n}, {a.threads} thread(s), {a.rounds} rounds of {a.steps} steps; "
          f"touching wall: {touched} particles within reach")
    print(f"{'variant':<20} {'ns/particle/step':>17} {'vs piston (median of rounds)':>29}")
    for k in kinds:
        t = np.array(times[k])
        print(f"{k:<20} {np.median(t):17.2f} {np.median(t - base):+29.2f}")

    # the drives' own work per step, timed alone (same hooks, same order as in DampedVerlet.step)
    print(f"drive hooks alone, {a.calls} calls: us per step, ns per particle and step")
    for k in kinds:
        s, dyn, cons = runs[k]
        atoms = s.atoms
        p = atoms.arrays["momenta"]
        f = dyn.forces
        h = 0.5 * dyn.dt
        x0, p0, f0 = atoms.positions.copy(), p.copy(), f.copy()
        t0 = time.perf_counter()
        for _ in range(a.calls):
            for c in cons:
                c.begin_step()
            for c in cons:
                c.adjust_momenta(atoms, p)
            for c in cons:
                c.end_drift()
            for c in cons:
                c.adjust_forces(atoms, f)
            for c in cons:
                c.kick_extra(p, h)
            for c in cons:
                c.adjust_momenta(atoms, p)
        us = (time.perf_counter() - t0) / a.calls * 1e6
        atoms.positions[:] = x0
        p[:] = p0
        f[:] = f0
        print(f"{k:<20} {us:10.1f} us {us * 1e3 / n:8.3f} ns")


if __name__ == "__main__":
    main()

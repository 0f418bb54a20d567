"""clusterdyn's own settings on the race's scene: does another skin or table size run faster?

    python benchmarks/cd_settings.py                 # -> results/cd_settings.{md,json}

``lammps_tune.py`` tunes LAMMPS' table, skin and rebuild check before racing it;
this script asks the same of clusterdyn.  From the saved 128k piston-shock state
with 30% of the sample shocked (``benchmarks/_states.py``), each configuration
(``ClusterDynamics(skin=..., n_table=...)``, the rest as saved) runs ``--warm``
steps, then ``--steps`` timed steps (one thread, process clock); the
configurations alternate within each of ``--repeat`` rounds, and the best round
counts.  The force error is that of the configuration's table against the
default table (10407 bins) on the state, relative to the largest force.
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _states import write_report  # noqa: E402
RESULTS = HERE / "results"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--skins", default="0.15,0.2,0.25,0.3", help="skins tried with the default table, r0")
    ap.add_argument("--tables", default="1000,2000,5000", help="table sizes tried with the default skin")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--warm", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(RESULTS / "cd_settings"))
    a = ap.parse_args(argv)
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.calculators.cluster import default_skin
    from clusterdyn.parallel import set_max_threads
    from clusterdyn.potentials import N_BINS
    from _states import load_state, shock_state
    set_max_threads(1)
    path = shock_state(128, 0.3)
    atoms, _, _ = load_state(path)
    rc = float(atoms.calc.parameters.rc)
    skin0 = default_skin(rc)
    configs = [(float(s), N_BINS) for s in a.skins.split(",")]
    configs += [(skin0, int(t)) for t in a.tables.split(",")]
    if (skin0, N_BINS) not in configs:
        configs.insert(0, (skin0, N_BINS))
    ref = atoms.get_forces()
    fmax = np.abs(ref).max()

    def configure(atoms, skin, nt):
        """The Atoms' calculator replaced by one with this skin and table, the rest as saved (a
        dynamics on them takes it up at its next step)."""
        atoms.calc = ClusterDynamics(**dict(atoms.calc.parameters, skin=skin, n_table=nt))

    err = {}
    for skin, nt in configs:
        configure(atoms, skin, nt)
        err[skin, nt] = float(np.abs(atoms.get_forces() - ref).max() / fmax)
    rates = {c: [] for c in configs}
    builds = {c: [] for c in configs}
    for rep in range(a.repeat):
        for skin, nt in configs:
            atoms, dyn, _ = load_state(path)
            configure(atoms, skin, nt)
            dyn.run(a.warm)
            b0 = atoms.calc.nl.nbuilds
            t0 = time.process_time()
            dyn.run(a.steps)
            t = time.process_time() - t0
            rates[skin, nt].append(len(atoms) * a.steps / t)
            builds[skin, nt].append(atoms.calc.nl.nbuilds - b0)
            print(f"round {rep + 1}: skin {skin:g} r0, table {nt}: {rates[skin, nt][-1]:.3g} particle-steps/s, "
                  f"{builds[skin, nt][-1]} builds", flush=True)
    best0 = max(rates[skin0, N_BINS])
    rows = [{"skin_r0": s, "n_table": nt, "rate": max(rates[s, nt]), "rates": rates[s, nt],
             "relative": max(rates[s, nt]) / best0, "builds": builds[s, nt], "force_error": err[s, nt],
             "default": (s, nt) == (skin0, N_BINS)} for s, nt in configs]
    meta = {"N": len(atoms), "steps": a.steps, "repeat": a.repeat, "load": os.getloadavg()[0],
            "date": time.strftime("%Y-%m-%d %H:%M")}
    L = ["# clusterdyn's skin and table size on the race's scene", "",
         f"{meta['date']}: `python benchmarks/cd_settings.py --steps {a.steps} --repeat {a.repeat}`; 128k piston "
         f"shock from the 30%-shocked state, N = {meta['N']}, one thread, process clock, best of {a.repeat} "
         f"rounds; load average {meta['load']:.1f}.  Default: skin {skin0:g} r0, {N_BINS} bins.", "",
         "| skin / r0 | table bins | particle-steps/s | x default | builds / steps | force error | all rounds |",
         "|---:|---:|---:|---:|---|---:|---|"]
    for r in rows:
        L.append(f"| {r['skin_r0']:g}{' (default)' if r['default'] else ''} | {r['n_table']} | {r['rate']:.3g} | "
                 f"{r['relative']:.2f} | {max(r['builds'])} / {a.steps} | {r['force_error']:.1e} | "
                 + ", ".join(f"{x:.3g}" for x in r["rates"]) + " |")
    print(f"wrote {write_report(a.out, {'meta': meta, 'rows': rows}, L)}")


if __name__ == "__main__":
    main()

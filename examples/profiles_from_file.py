"""Profiles of the main job from its H5MD file alone, against the profiles computed during the run.

Runs the main job (``clusterdyn run shock``: Al, u = 3 km/s, [100], 100x8x8 cells) with the
scene's own builder, H5MD writer set-up and frame loop, and records the slab profiles live on
every frame the writer writes (``ProfileRecorder``, virials from the running calculator).
Then ``trajectory_profiles(path, exclude="drives")`` computes them again from the file alone
(calculator, slab width and piston from the file's metadata) and the two are compared.

Run: python examples/profiles_from_file.py [OUTDIR]
"""

import os
import sys
import time
from pathlib import Path

import numpy as np

from clusterdyn import units
from clusterdyn.analysis.profiles import ProfileRecorder, trajectory_profiles
from clusterdyn.io import H5MDWriter
from clusterdyn.scenes.shock import build_shock, run_shock

out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/profiles_from_file")
out.mkdir(parents=True, exist_ok=True)
path = out / "shock.h5md"
# the main job's defaults (CLUSTERDYN_EXAMPLES_TINY=1, as the tests run it: a 40x3x3 sample)
setup = build_shock(size=(40, 3, 3)) if os.environ.get("CLUSTERDYN_EXAMPLES_TINY") == "1" else build_shock()
atoms, calc, dyn = setup.atoms, setup.calc, setup.dyn
area = atoms.cell[1, 1] * atoms.cell[2, 2]
obs = {"piston_force": (lambda a: -setup.piston.force[0] / units.N, "N"),
       "piston_pressure": (lambda a: -setup.piston.force[0] / area / units.GPa, "GPa")}
interval = max(1, setup.nsteps // 20)                   # h5md_frames = 20, as the scene
rec = ProfileRecorder(np.sqrt(2) * calc.potentials[0].r0)   # the default slab of the file analysis


def live():
    vir = calc.compute(atoms, per_particle=True)["virials"].copy()
    rec.add(atoms, vir, dyn.get_time(), exclude=setup.piston_mask)


t0 = time.perf_counter()
with H5MDWriter(str(path), atoms, dyn=dyn, observables=obs) as writer:
    dyn.attach(writer, interval=interval)
    dyn.attach(live, interval=interval)
    tracker, state, t_run = run_shock(setup, 60, progress=False)
print(f"main job: {len(atoms)} clusters, {setup.nsteps} steps, D = {state.D_fit / units.km_s:.6g} km/s "
      f"({time.perf_counter() - t0:.1f} s)")

ref = rec.arrays()
t0 = time.perf_counter()
prof = trajectory_profiles(path, exclude="drives")
print(f"from the file: {len(prof['t'])} frames x {len(prof['x'])} slabs of "
      f"{prof['width'] / units.um:.6g} um ({time.perf_counter() - t0:.1f} s)")
for k in ("count", "density", "velocity", "stress", "von_mises", "pressure", "t"):
    a, b = np.asarray(prof[k], float), np.asarray(ref[k], float)
    print(f"  {k:10s} max |file - live| / max |live| = {np.abs(a - b).max() / np.abs(b).max():.3g}")

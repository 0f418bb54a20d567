"""A piston shock through the Python API: build, attach a calculator, drive, track the front.

Run: python examples/shock_python_api.py
"""

import os

import numpy as np

from clusterdyn import units
from clusterdyn.analysis.shock import ShockTracker
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.materials import hugoniot
from clusterdyn.md import DampedVerlet, Piston

r0 = 5 * units.um
u = 4 * units.km_s
tiny = os.environ.get("CLUSTERDYN_EXAMPLES_TINY") == "1"   # the tests' setting: a shorter run
atoms = fcc_packing("Al", r0, size=(24, 3, 3) if tiny else (40, 4, 4), pbc=(False, True, True))
atoms.calc = ClusterDynamics(rc=1.15)

# the first two atomic planes are the piston
piston = atoms.positions[:, 0] < 0.75 * r0
atoms.set_constraint(Piston(piston, u))
rng = np.random.default_rng(0)
v = rng.normal(0, 10 * units.m_s / np.sqrt(3), (len(atoms), 3))   # 10 m/s rms breaks the symmetry
v[piston] = 0
atoms.set_velocities(v)                                             # the piston constraint sets u

dyn = DampedVerlet(atoms, J=None)          # Hugoniot runs: no damping term at all
tracker = ShockTracker(atoms.calc.potentials[0].material.rho0, u, width=np.sqrt(2) * r0)


def frame():
    vir = atoms.calc.compute(atoms, per_particle=True)["virials"]
    tracker.add(dyn.get_time(), atoms, vir, atoms.positions[piston, 0].max(), exclude=piston)


dyn.attach(frame, interval=40)
dyn.run(600 if tiny else 1200)
state = tracker.result()
ref = hugoniot("Al").D(u)
print(f"D = {state.D_fit / units.km_s:.3f} km/s (Al-1100: {ref / units.km_s:.3f} km/s, "
      f"error {100 * (state.D_fit / ref - 1):+.2f}%), steady: {state.steady}")
print(f"behind the front: u = {state.u / units.km_s:.3f} km/s, rho = {state.rho / units.g_cm3:.3f} g/cm3, "
      f"P = {state.P / units.GPa:.1f} GPa (rho0 D u = {state.P_momentum / units.GPa:.1f} GPa)")

"""Write an H5MD trajectory of a shock and analyse it from the file alone.

With MDAnalysis (density profile along x from the Universe's masses) and with
clusterdyn's own profiles (stress too: the calculator is rebuilt from the
file's metadata).

Run: python examples/read_h5md_mdanalysis.py [OUTDIR]
"""

import sys
from pathlib import Path

import numpy as np

from clusterdyn import units
from clusterdyn.analysis.profiles import trajectory_profiles
from clusterdyn.io.mda import universe
from clusterdyn.scenes import get_scene

out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/example_h5md")
get_scene("shock").run({"size": "30x3x3", "frames": 20, "h5md_frames": 10}, out=out, progress=False)
path = out / "shock.h5md"

u = universe(path)                     # masses, ids, material ids from the file; no warnings
print(f"{u.atoms.n_atoms} clusters of {sorted(set(u.atoms.types))}, {u.trajectory.n_frames} frames, "
      f"t = {u.trajectory[0].time:.0f} .. {u.trajectory[-1].time:.0f} ps, "
      f"total mass {u.atoms.total_mass():.4g} amu")
masses = u.atoms.masses
for ts in u.trajectory[::3]:
    x = ts.positions[:, 0]
    area = ts.dimensions[1] * ts.dimensions[2]
    edges = np.linspace(x.min(), x.max(), 11)
    m, _ = np.histogram(x, edges, weights=masses)
    rho = m / (area * np.diff(edges)) * 1.66054                         # amu/A^3 -> g/cm3
    print(f"t = {ts.time / 1000:7.2f} ns  rho(x) [g/cm3]: " + " ".join(f"{r:4.2f}" for r in rho))

prof = trajectory_profiles(path, exclude="drives")   # slabs of sqrt(2) r0, the piston left out
f = -1
sxx = -prof["stress"][f, :, 0] / units.GPa
print(f"last frame: largest -sigma_xx {np.nanmax(sxx):.3g} GPa over {len(prof['x'])} slabs "
      f"of {prof['width'] / units.um:.3g} um")

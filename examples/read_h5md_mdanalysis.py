"""Write an H5MD trajectory of a shock and analyse it with MDAnalysis (density profile along x).

Run: python examples/read_h5md_mdanalysis.py [OUTDIR]
"""

import sys
from pathlib import Path

import h5py
import MDAnalysis as mda
import numpy as np

from clusterdyn.scenes import get_scene

out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/example_h5md")
get_scene("shock").run({"size": "30x3x3", "frames": 20, "h5md_frames": 10}, out=out, progress=False)

u = mda.Universe(str(out / "shock.h5md"))          # no topology file needed
print(f"{u.atoms.n_atoms} clusters, {u.trajectory.n_frames} frames, "
      f"t = {u.trajectory[0].time:.0f} .. {u.trajectory[-1].time:.0f} ps")
with h5py.File(out / "shock.h5md", "r") as f:                       # per-particle masses, amu
    masses = f["particles/trajectory/mass/value"][0]
for ts in u.trajectory[::3]:
    x = ts.positions[:, 0]
    area = ts.dimensions[1] * ts.dimensions[2]
    edges = np.linspace(x.min(), x.max(), 11)
    m, _ = np.histogram(x, edges, weights=masses)
    rho = m / (area * np.diff(edges)) * 1.66054                         # amu/A^3 -> g/cm3
    print(f"t = {ts.time / 1000:7.2f} ns  rho(x) [g/cm3]: " + " ".join(f"{r:4.2f}" for r in rho))

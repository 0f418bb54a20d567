"""Build cluster packings: an oriented fcc block, a carved sphere, and look at them.

Run: python examples/build_packing.py [OUTDIR]
"""

import sys
from pathlib import Path

import numpy as np
from ase.io import write

from clusterdyn import units
from clusterdyn.build import Sphere, fcc_packing

out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/examples")
out.mkdir(parents=True, exist_ok=True)

r0 = 5 * units.um
block = fcc_packing("Al", r0, size=(6, 4, 4), direction="111", pbc=(False, True, True))
rho = block.get_masses().sum() / block.get_volume()
print(f"[111] block: {len(block)} clusters, density {rho / units.g_cm3:.4f} g/cm3 (Al: 2.71)")

ball = fcc_packing("Pb", r0, shape=Sphere(center=(0, 0, 0), radius=6 * r0))
print(f"Pb sphere of radius 6 r0: {len(ball)} clusters, cluster mass "
      f"{ball.get_masses()[0] / units.kg:.3e} kg")
assert np.all(ball.arrays["material"] == 0) and ball.info["cd_materials"] == ["Pb"]

write(out / "block111.xyz", block)
print(f"wrote {out / 'block111.xyz'}")

"""Checkpoint a damped run with a piston, restart it, and check it matches an uninterrupted run.

Run: python examples/restart_run.py [OUTDIR]
"""

import sys
from pathlib import Path

import numpy as np

from clusterdyn import units
from clusterdyn.io.checkpoint import load_run, save_run
from clusterdyn.scenes.shock import build_shock

out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/example_restart")
out.mkdir(parents=True, exist_ok=True)

ref = build_shock(size=(16, 3, 3), u=2 * units.km_s, J=50)
ref.dyn.run(400)

run = build_shock(size=(16, 3, 3), u=2 * units.km_s, J=50)
run.dyn.run(200)
save_run(out / "half.h5", run.dyn)
print(f"checkpoint at step {run.dyn.nsteps}: {out / 'half.h5'}")

atoms, dyn, _ = load_run(out / "half.h5")   # e.g. in a new process
dyn.run(200)
same = np.array_equal(atoms.positions, ref.atoms.positions)
print(f"restarted run at step {dyn.nsteps}; bit-identical to the uninterrupted run: {same}")
assert same

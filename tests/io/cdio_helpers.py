"""Small systems and short ASE runs shared by the io tests (imported by conftest and tests)."""

import numpy as np
from ase import units
from ase.build import bulk
from ase.calculators.emt import EMT
from ase.md.verlet import VelocityVerlet


def make_atoms(seed=0, shuffle_ids=True):
    """32 rattled Cu atoms (periodic, EMT) with velocities, id and material arrays."""
    rng = np.random.default_rng(seed)
    atoms = bulk("Cu", cubic=True).repeat(2)
    atoms.rattle(0.05, seed=seed)
    n = len(atoms)
    ids = rng.permutation(n) + 100 if shuffle_ids else np.arange(n) + 100
    atoms.new_array("id", ids)
    atoms.new_array("material", (ids % 2).astype(np.int64))
    atoms.set_momenta(rng.normal(0.0, 0.5, (n, 3)))
    atoms.calc = EMT()
    return atoms


class Recorder:
    """Observer copying what the writer should store, rows in id order."""

    def __init__(self, atoms, dyn):
        self.atoms, self.dyn, self.frames = atoms, dyn, []

    def __call__(self):
        a = self.atoms
        order = np.argsort(a.arrays["id"], kind="stable")
        self.frames.append({
            "step": self.dyn.nsteps,
            "time": self.dyn.get_time(),
            "positions": a.positions[order].copy(),
            "velocities": a.get_velocities()[order],
            "forces": a.calc.get_property("forces", a)[order],
            "energy": a.calc.get_property("energy", a),
            "ekin": a.get_kinetic_energy(),
            "cell": a.cell[:].copy(),
            "numbers": a.numbers[order].copy(),
            "masses": a.get_masses()[order],
            "id": a.arrays["id"][order].copy(),
            "material": a.arrays["material"][order].copy(),
        })


def run_md(path, steps=10, interval=2, atoms=None, **writer_kw):
    """Run VelocityVerlet on ``atoms`` writing H5MD to ``path``; return (atoms, dyn, recorder)."""
    from clusterdyn.io import H5MDWriter
    atoms = make_atoms() if atoms is None else atoms
    dyn = VelocityVerlet(atoms, timestep=2 * units.fs)
    rec = Recorder(atoms, dyn)
    with H5MDWriter(path, atoms, dyn=dyn, **writer_kw) as writer:
        dyn.attach(writer, interval=interval)
        dyn.attach(rec, interval=interval)
        dyn.run(steps)
    return atoms, dyn, rec

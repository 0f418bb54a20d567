"""What a linked pair inherits at a switch: its automata's tensors (the default) or, with
``inherit = "pairs"``, its own state if it survives; the load on a face layer through a switch."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build.mca import mca_packing
from clusterdyn.build.shapes import Cylinder
from clusterdyn.errors import InputError
from clusterdyn.mca import MCA, MCADynamics


def _squeezed(inherit):
    D0 = 6 * units.mm
    d = D0 / 6
    atoms = mca_packing("Al6061-T6", d, Cylinder(center=(0.5 * D0 + d, 0.5 * D0 + d, 0.0), radius=0.5 * D0,
                                                 length=1.2 * D0, axis=2), "fcc")
    atoms.calc = MCA()
    dyn = MCADynamics(atoms, damping=0.0, remesh_strain=0.1)
    dyn.state.set_inherit(inherit)
    atoms.set_positions(atoms.positions @ np.diag([1.0 + 1e-3, 1.0 + 1e-3, 1.0 - 2e-3]).T)
    dyn._evaluate(commit=True)
    z = atoms.positions[:, 2]
    bottom = z < z.min() + 0.25 * d
    f0 = -atoms.calc.get_forces(atoms)[bottom, 2].sum()      # the body pushes the layer down
    sig0 = {tuple(k): v.copy() for k, v in zip(dyn.state.pid_p2, dyn.state.sig_p2)}
    dyn.remesh()
    f1 = -atoms.calc.get_forces(atoms)[bottom, 2].sum()
    st = dyn.state
    kept = [np.array_equal(sig0[tuple(k)], v) for k, v, lk in zip(st.pid_p2, st.sig_p2, st.linked_p)
            if tuple(k) in sig0 and lk == 1]
    return f0, f1, kept


def test_surviving_pairs_keep_the_load_on_a_face_layer():
    f0, f1, kept = _squeezed("automata")
    assert f0 > 0 and f1 < 0.8 * f0            # the surface automata's tensors lose the face's load (0.67)
    f0p, f1p, keptp = _squeezed("pairs")
    assert f0p == f0
    assert abs(f1p / f0p - 1) < 0.02           # only the contact areas' update
    assert all(keptp) and len(keptp) > 100 and not all(kept)
    from clusterdyn.mca.state import MCAState
    with pytest.raises(InputError, match="inherit"):
        MCAState.set_inherit(MCAState.__new__(MCAState), "tensors")

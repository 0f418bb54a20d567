"""Longitudinal and shear pulses travel at sqrt((K + 4G/3)/rho) and sqrt(G/rho) within 3%."""

import numpy as np
import pytest
from scipy.special import erf

from clusterdyn.build.mca import mca_packing
from clusterdyn.mca.calculator import MCA
from clusterdyn.mca.dynamics import MCADynamics, wave_speeds
from clusterdyn.analysis.mca_elastic import elastic_material


def pulse_speed(packing, mode, nu=0.25, L=40.0, w=5.0):
    """Speed of a right-moving Gaussian pulse in a bar periodic across its width."""
    mat = elastic_material(nu)
    atoms = mca_packing(mat, 1.0, (L, 4.3, 4.3), packing, pbc=(False, True, True))
    atoms.calc = MCA()
    atoms.calc.setup(atoms)                       # reference: the undeformed bar
    cl, cs = wave_speeds(mat)
    c = cl if mode == "L" else cs
    comp = 0 if mode == "L" else 1
    x = atoms.positions[:, 0]
    x0, amp = 0.3 * L, 1e-3 * c
    g = np.exp(-((x - x0) / w) ** 2)
    v = np.zeros((len(atoms), 3))
    v[:, comp] = amp * g                          # u(x - ct): v = -c u'
    pos = atoms.positions.copy()
    pos[:, comp] += -(amp / c) * w * np.sqrt(np.pi) / 2 * (erf((x - x0) / w) + 1)
    if mode == "S":                               # automata rotate with the material spin
        atoms.arrays["theta"][:, 2] = -0.5 * (amp / c) * g
        atoms.arrays["omega"][:, 2] = 0.5 * amp * g * (-2 * (x - x0) / w ** 2)
    atoms.positions = pos
    atoms.set_velocities(v)
    dyn = MCADynamics(atoms)
    n = int(0.35 * L / c / dyn.dt) // 15
    m = atoms.get_masses()
    ts, xs = [], []
    for _ in range(15):
        dyn.run(n)
        ke = m * atoms.get_velocities()[:, comp] ** 2
        ts.append(dyn.state.time)
        xs.append((atoms.positions[:, 0] * ke).sum() / ke.sum())
    return np.polyfit(ts[1:], xs[1:], 1)[0] / c


@pytest.mark.parametrize("packing,mode", [("sc", "L"), ("sc", "S"), ("fcc", "L"), ("fcc", "S")])
def test_wave_speed(packing, mode):
    assert pulse_speed(packing, mode) == pytest.approx(1.0, abs=0.03)

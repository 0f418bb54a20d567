"""The drive and wall family: U(t) pistons, harmonic walls, tractions; in DampedVerlet and ASE's dynamics."""

import json

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

from clusterdyn import units
from clusterdyn.build import fcc_packing, make_cluster_atoms
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError, InstabilityError
from clusterdyn.io.checkpoint import load_run, save_run
from clusterdyn.md import DampedVerlet, Piston, SmoothRamp, Table, Traction, Wall, from_state
from clusterdyn.scenes.shock import build_shock

R0 = 5 * units.um
U = 2 * units.km_s


def shock_with(velocity, J=None, size=(16, 3, 3), seed=2):
    """The shock scene's sample and time step, its piston replaced by one of history ``velocity``."""
    s = build_shock(size=size, u=U, J=J, seed=seed)
    p = Piston(s.piston.index, velocity)
    s.atoms.set_constraint(p)
    s.atoms.set_momenta(s.atoms.get_momenta())
    dyn = DampedVerlet(s.atoms, timestep=s.dyn.dt, J=J)
    return s, p, dyn


def test_constant_table_gives_the_constant_pistons_run_bit_for_bit():
    runs = []
    for vel in (U, Table([0.0, 1.0 * units.s], [U, U])):
        s, p, dyn = shock_with(vel, J=50)
        dyn.run(150)
        assert s.calc.nl.nbuilds > 1
        runs.append((s.atoms.positions.copy(), s.atoms.get_momenta(), p.force.copy(), p.impulse.copy(), p.work))
    (x1, p1, f1, i1, w1), (x2, p2, f2, i2, w2) = runs
    assert np.array_equal(x1, x2) and np.array_equal(p1, p2)
    assert np.array_equal(f1, f2) and np.array_equal(i1, i2) and w1 == w2


def test_ramp_momentum_given_equals_the_reaction_impulse():
    """Under U(t) = ramp to U then hold, the sample's momentum change is minus the trapezoid
    integral of the piston's reaction (1e-6); the layer moved by the integral of U."""
    T = 60 * build_shock(size=(16, 3, 3), u=U).dyn.dt
    s, p, dyn = shock_with(Table([0.0, T, 10 * T], [0.0, U, U]), J=50)
    mob = np.ones(len(s.atoms), bool)
    mob[p.index] = False
    P0 = s.atoms.get_momenta()[mob].sum(axis=0)
    x0 = s.atoms.positions[p.index].copy()
    dyn.run(150)
    dP = s.atoms.get_momenta()[mob].sum(axis=0) - P0
    assert abs(dP[0] / p.impulse[0] - 1) < 1e-6
    assert np.abs(dP - p.impulse).max() < 1e-6 * abs(p.impulse[0])
    t = dyn.get_time()
    X = 0.5 * U * T + U * (t - T)                           # integral of U from 0 to t
    np.testing.assert_allclose(s.atoms.positions[p.index, 0] - x0[:, 0], X, rtol=1e-12)
    assert np.array_equal(s.atoms.positions[p.index, 1:], x0[:, 1:])
    v = s.atoms.get_velocities()[p.index]
    np.testing.assert_allclose(v, np.broadcast_to([U, 0, 0], v.shape), rtol=1e-14)
    assert p.work > 0 and p.t_sample == t


def test_piston_in_any_direction_and_in_ase_velocity_verlet():
    """A U(t) piston bound to ase.md.verlet.VelocityVerlet: its displacement is the integral of U."""
    a = fcc_packing("Al", R0, size=(2, 2, 2), pbc=False)
    d = np.array([1.0, -1.0, 2.0]) / np.sqrt(6.0)
    top = a.positions @ d
    mask = top > top.max() - 0.6 * R0
    a.calc = ClusterDynamics()
    a.calc.setup(a)
    dt = 0.03 * R0 / a.calc.potentials[0].c0
    T = 40 * dt
    for vel in (Table([0.0, T], [0.0, U]), lambda t: U * min(t / T, 1.0)):
        b = a.copy()
        b.calc = ClusterDynamics()
        p = Piston(mask, vel, direction=d)
        b.set_constraint(p)
        x0 = b.positions.copy()
        dyn = VelocityVerlet(b, timestep=dt)
        p.bind(dyn)
        dyn.run(60)
        t = dyn.get_time()
        X = 0.5 * U * T + U * (t - T)
        disp = b.positions[mask] - x0[mask]
        np.testing.assert_allclose(disp, np.tile(X * d, (mask.sum(), 1)), rtol=1e-10, atol=1e-12 * R0)
        np.testing.assert_allclose(b.get_velocities()[mask], np.tile(U * d, (mask.sum(), 1)), rtol=1e-12)
        assert p.impulse @ d > 0                                   # it pushed the block
    unbound = Piston(mask, Table([0.0, T], [0.0, U]))
    a.set_constraint(unbound)
    with pytest.raises(InputError, match="bind"):
        VelocityVerlet(a, timestep=dt).run(1)


def one_cluster(normal, d0, v0):
    a = make_cluster_atoms(np.zeros((1, 3)), ["Al"], [R0])
    a.calc = ClusterDynamics()
    w = Wall(-d0 * normal, normal)
    a.set_constraint(w)
    a.set_velocities([v0])
    return a, w


def test_one_cluster_rebounds_from_the_wall_energy_conserved():
    n = np.array([1.0, 2.0, -0.5])
    n /= np.linalg.norm(n)
    v0 = -200 * units.m_s * n + 50 * units.m_s * np.array([0.0, 0.5, 1.0])
    a, w = one_cluster(n, 0.55 * R0, v0)
    K, dc = w.resolve(a)
    p = a.calc.potentials[0]
    assert K[0] == pytest.approx(0.5 * p.stiffness(p.r0), rel=1e-15) and dc[0] == 0.5 * R0
    omega = np.sqrt(2 * K[0] / a.get_masses()[0])
    dyn = DampedVerlet(a, timestep=0.001 / omega, J=None)       # resolves the wall's stiffness
    E0 = dyn.get_total_energy()
    steps = int(np.ceil((0.1 * R0 / (200 * units.m_s) + np.pi / omega) / dyn.dt))
    worst = 0.0
    for _ in range(10):
        dyn.run(steps // 10 + 1)
        worst = max(worst, abs(dyn.get_total_energy() - E0))
    v = a.get_velocities()[0]
    assert a.positions[0] @ n + 0.55 * R0 > 0.5 * R0 and w.energy == 0.0         # left the wall
    assert abs(v @ n / (v0 @ n) + 1) < 1e-6                                        # normal velocity reversed
    vt, vt0 = v - (v @ n) * n, v0 - (v0 @ n) * n
    assert np.abs(vt - vt0).max() < 1e-12 * np.linalg.norm(v0)                     # frictionless
    assert abs(dyn.get_total_energy() - E0) < 1e-6 * E0 and worst < 1e-6 * E0
    m = a.get_masses()[0]
    np.testing.assert_allclose(w.impulse, m * (v - v0), rtol=1e-12, atol=1e-12 * m * np.linalg.norm(v0))
    assert w.work == 0.0


@pytest.mark.parametrize("J", [None, 50.0])
def test_block_momentum_change_is_the_wall_impulse(J):
    a = fcc_packing("Al", R0, size=(2, 2, 2), pbc=False)
    a.calc = ClusterDynamics()
    n = np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0)
    low = (a.positions @ n).min()
    w = Wall((low - 0.6 * R0) * n, n)
    a.set_constraint(w)
    rng = np.random.default_rng(1)
    a.set_velocities(-300 * units.m_s * n + rng.normal(0, 20 * units.m_s, (len(a), 3)))
    P0 = a.get_momenta().sum(axis=0)
    dyn = DampedVerlet(a, J=J)
    dyn.run(900)
    dP = a.get_momenta().sum(axis=0) - P0
    assert w.impulse @ n > 1.5 * abs(P0 @ n)                       # it bounced
    assert np.abs(dP - w.impulse).max() < 1e-9 * np.linalg.norm(w.impulse)


def test_particle_behind_the_wall_is_an_instability():
    n = np.array([0.0, 0.0, 1.0])
    a, w = one_cluster(n, 0.55 * R0, -8 * units.km_s * n)
    dyn = DampedVerlet(a, timestep=0.01 * R0 / (5 * units.km_s), J=None)
    with pytest.raises(InstabilityError, match="behind the wall plane.*step .*particle 0.*distance") as exc:
        dyn.run(200)
    assert exc.value.step > 0 and exc.value.value < 0


def test_sticking_wall_holds_the_tangential_velocity():
    n = np.array([0.0, 0.0, 1.0])
    v0 = np.array([100.0, 0.0, -100.0]) * units.m_s
    a = make_cluster_atoms(np.zeros((1, 3)), ["Al"], [R0])
    a.calc = ClusterDynamics()
    w = Wall(-0.45 * R0 * n, n, sticking=True)                   # touching from the start
    a.set_constraint(w)
    a.set_velocities([v0])
    dyn = DampedVerlet(a, J=None)
    dyn.run(50)
    v = a.get_velocities()[0]
    assert v[0] == 0.0 and v[1] == 0.0 and w.dissipated > 0
    np.testing.assert_allclose(w.impulse, a.get_momenta()[0] - a.get_masses()[0] * v0, rtol=1e-10,
                               atol=1e-10 * a.get_masses()[0] * 100 * units.m_s)


def traction_block(J=50.0):
    """A block on a wall (bottom, normal +y), a traction layer on top pressing and shearing along z,
    a U(t) piston at the low-x face; periodic along z."""
    a = fcc_packing("Al", R0, size=(4, 3, 2), pbc=(False, False, True))
    a.calc = ClusterDynamics()
    y = a.positions[:, 1]
    x = a.positions[:, 0]
    top = y > y.max() - 0.3 * R0
    left = (x < x.min() + 0.3 * R0) & ~top
    wall = Wall([0.0, y.min() - 0.501 * R0, 0.0], [0.0, 1.0, 0.0])
    L = a.cell.lengths()
    area = (x.max() - x.min() + R0 / np.sqrt(2)) * L[2]
    tr = Traction(top, [0.0, 1.0, 0.0], 0.2 * units.GPa, Table([0.0, 2 * units.ns], [0.0, 20 * units.m_s]),
                  tangent=[0.0, 0.0, 1.0], area=area)
    pis = Piston(left, Table([0.0, 1 * units.ns, 3 * units.ns], [0.0, 50 * units.m_s, 0.0]))
    a.set_constraint([pis, wall, tr])
    a.set_momenta(a.get_momenta())
    return a, DampedVerlet(a, J=J), (pis, wall, tr)


def test_traction_presses_rigidly_and_shears():
    """A block between a wall (below) and a traction layer (above, 1 GPa, sheared along z): the layer
    moves rigidly, tangentially by the integral of U_t, along the normal by M dv_n/dt = R_n - sigma A."""
    a = fcc_packing("Al", R0, size=(2, 2, 2), pbc=(True, False, True))
    a.calc = ClusterDynamics()
    y = a.positions[:, 1]
    top = y > y.max() - 0.3 * R0
    wall = Wall([0.0, y.min() - 0.501 * R0, 0.0], [0.0, 1.0, 0.0])
    ut = Table([0.0, 2 * units.ns], [0.0, 20 * units.m_s])
    sigma = 1 * units.GPa
    tr = Traction(top, [0.0, 1.0, 0.0], sigma, ut, tangent=[0.0, 0.0, 1.0])
    a.set_constraint([wall, tr])
    x0 = a.positions.copy()
    dyn = DampedVerlet(a, J=10)
    dyn.run(600)
    L = a.cell.lengths()
    assert tr.area == pytest.approx(L[0] * L[2], rel=1e-14)          # derived: the periodic face
    d = a.positions[tr.index] - x0[tr.index]
    assert np.ptp(d, axis=0).max() < 1e-9 * R0                        # rigid
    t = dyn.get_time()
    np.testing.assert_allclose(d[:, 2], ut.integral(0.0, t), rtol=1e-10)
    assert np.abs(d[:, 0]).max() < 1e-9 * R0 and d[0, 1] < 0          # pressed down
    # the layer's normal motion: M v_n = int (R_n - sigma A) dt = -impulse_n - sigma A t
    lhs = tr.mass * tr.normal_velocity
    assert abs(lhs - (-tr.impulse[1] - sigma * tr.area * t)) < 1e-9 * sigma * tr.area * t
    v = a.get_velocities()[tr.index]
    np.testing.assert_allclose(v[:, 1], tr.normal_velocity, rtol=1e-12)
    assert tr.friction[1] == 0.0 and tr.friction[2] == tr.force[2]
    dP = a.get_momenta()[~top].sum(axis=0)                           # the block started at rest
    np.testing.assert_allclose(dP, wall.impulse + tr.impulse, rtol=0, atol=1e-9 * sigma * tr.area * t)
    assert abs(tr.normal_position - (x0[tr.index, 1].mean() + d[0, 1])) < 1e-9 * R0


def test_fast_path_runs_with_any_mix_of_drives_bit_for_bit():
    """Piston + wall + traction: every step takes the fused passes, and they give the separate
    passes' trajectory bit for bit (the wall's extra kick comes in the same order in both)."""
    runs = []
    for fused in (True, False):
        a, dyn, drives = traction_block()
        calls = []
        adv = a.calc.engine.advance
        a.calc.engine.advance = (lambda *x, _adv=adv, _c=calls: _c.append(1) or _adv(*x)) if fused \
            else (lambda *x: None)
        dyn.run(100)
        assert (len(calls) == 100) == fused
        assert drives[1].impulse[1] > 0
        runs.append((a.positions.copy(), a.get_momenta(), [d.impulse.copy() for d in drives]))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert all(np.array_equal(x, y) for x, y in zip(runs[0][2], runs[1][2]))


def test_save_load_run_with_piston_wall_traction_is_bit_identical(tmp_path):
    N = 120
    a, d, drives = traction_block()
    d.run(2 * N)
    b, e, _ = traction_block()
    e.run(N)
    save_run(tmp_path / "run.h5", e, extra={"note": "half"})
    c, f, extra = load_run(tmp_path / "run.h5")
    assert extra == {"note": "half"} and f.nsteps == N
    assert [type(x).__name__ for x in c.constraints] == ["Piston", "Wall", "Traction"]
    f.run(N)
    assert np.array_equal(c.positions, a.positions) and np.array_equal(c.get_momenta(), a.get_momenta())
    for x, y in zip(c.constraints, drives):
        for k in ("force", "impulse"):
            assert np.array_equal(getattr(x, k), getattr(y, k)), (x, k)
        assert x.work == y.work and x.t_sample == y.t_sample
    assert drives[1].impulse[1] > 0 and drives[0].impulse[0] > 0 and drives[2].normal_velocity != 0.0
    assert c.constraints[2].normal_velocity == drives[2].normal_velocity
    assert c.constraints[2].normal_position == drives[2].normal_position


def test_callable_history_cannot_be_saved(tmp_path):
    s, p, dyn = shock_with(lambda t: U, size=(8, 3, 3))
    dyn.run(2)
    with pytest.raises(InputError, match="Table") as exc:
        save_run(tmp_path / "x.h5", dyn)
    assert "\n" not in str(exc.value) and not (tmp_path / "x.h5").exists()
    with pytest.raises(InputError, match="timestep"):
        DampedVerlet(s.atoms, J=None)                                  # no default dt from a callable


def test_free_lateral_piston_with_a_smooth_ramp():
    """``lateral="free"`` (a grip) in the fast path: the layer's speed along the direction is the
    smooth ramp's, its displacement the ramp's exact integral; across it the layer's particles
    move under their forces; the record holds only the force along the direction, and the
    momentum given to the sample along it is the recorded impulse (1e-6)."""
    T = 60 * build_shock(size=(16, 3, 3), u=U).dyn.dt
    s, p, dyn = shock_with(SmoothRamp(U, T), J=50)
    s.atoms.set_constraint(Piston(p.index, SmoothRamp(U, T), lateral="free"))
    dyn = DampedVerlet(s.atoms, timestep=dyn.dt, J=50)
    p = s.atoms.constraints[0]
    mob = np.ones(len(s.atoms), bool)
    mob[p.index] = False
    P0 = s.atoms.get_momenta()
    x0 = s.atoms.positions[p.index].copy()
    dyn.run(150)
    t = dyn.get_time()
    X = 0.5 * U * T + U * (t - T)                           # integral of the ramp from 0 to t
    np.testing.assert_allclose(s.atoms.positions[p.index, 0] - x0[:, 0], X, rtol=1e-12)
    v = s.atoms.get_velocities()[p.index]
    np.testing.assert_allclose(v[:, 0], U, rtol=1e-14)
    assert np.abs(v[:, 1:]).max() > 0 and np.abs(s.atoms.positions[p.index, 1:] - x0[:, 1:]).max() > 0
    assert np.all(p.force[1:] == 0.0) and p.force[0] < 0
    dP = s.atoms.get_momenta() - P0
    assert abs(dP[mob, 0].sum() / p.impulse[0] - 1) < 1e-6
    assert np.abs(dP[:, 1:].sum(axis=0)).max() < 1e-9 * abs(p.impulse[0])      # nothing taken across
    back = from_state(p.get_state())
    assert back.lateral == "free" and back.history.ramp_time == T and back.history.at(2 * T) == U
    assert SmoothRamp(U, T).mean(0.0, T) == pytest.approx(0.5 * U, rel=1e-14)


def test_state_and_describe_round_trip():
    w = Wall([0, 0, 1.0], [0, 0, 2.0], stiffness=3.0, cutoff=2.0)
    p = Piston([0, 1], Table([0.0, 1.0], [[0, 0, 0], [1.0, 2.0, 0]]))
    tr = Traction([2], [1, 0, 0], 1e-3, [0, 0.5, 0], area=10.0)
    for dr in (w, p, tr):
        st = dr.get_state()
        back = from_state(st)
        assert type(back) is type(dr)
        for k, v in st.items():
            if isinstance(v, np.ndarray):
                assert np.array_equal(back.get_state()[k], v)
        json.dumps(dr.describe())
    assert w.describe()["K_eV_per_A2"] == [3.0] and w.normal.tolist() == [0, 0, 1.0]


def test_table_from_csv(tmp_path):
    f = tmp_path / "u.csv"
    f.write_text("# VISAR-like history\nt_us,u_km_s\n0,0\n0.1,2.5\n1.0,2.5\n")
    t = Table.read_csv(f)
    assert np.allclose(t.times, [0, 0.1 * units.us, units.us]) and np.allclose(t.values[1], 2.5 * units.km_s)
    assert t.at(0.05 * units.us) == pytest.approx(1.25 * units.km_s, rel=1e-12)
    assert t.integral(0, units.us) == pytest.approx((0.5 * 0.1 * 2.5 + 0.9 * 2.5) * units.us * units.km_s, rel=1e-12)
    g = tmp_path / "v.csv"
    g.write_text("t_ns,ux_m_s,uy_m_s,uz_m_s\n0,1,2,3\n5,1,2,4\n")
    assert Table.read_csv(g).values.shape == (2, 3)


@pytest.mark.parametrize("make, arg", [
    (lambda: Wall([0, 0, 0], [0, 0, 0]), "normal"),
    (lambda: Traction([0], [0, 0, 0], 1.0), "normal"),
    (lambda: Piston([0], 1.0, direction=[0, 0, 0]), "direction"),
    (lambda: Wall([0, 0, 0], [1, 0, 0], stiffness=-1.0), "stiffness"),
    (lambda: Wall([0, 0, 0], [1, 0, 0], cutoff=0.0), "cutoff"),
    (lambda: Table([0.0, 1.0, 1.0], [0, 1, 2]), "times"),
    (lambda: Table([0.0, 2.0, 1.0], [0, 1, 2]), "times"),
    (lambda: Table([0.0, 1.0], [0, 1, 2]), "values"),
    (lambda: Piston([], 1.0), "indices"),
    (lambda: Traction([0], [1, 0, 0], 1.0, velocity=[1.0, 0, 0]), "velocity"),
    (lambda: Traction([0], [1, 0, 0], 1.0, velocity=2.0), "tangent"),
    (lambda: Wall([0, 0, 0], [1, 0, 0], sticking="yes"), "sticking"),
    (lambda: Piston([0], 1.0, lateral="sideways"), "lateral"),
    (lambda: Piston([0], [1.0, 0, 0], lateral="free"), "velocity"),
    (lambda: SmoothRamp(1.0, -1.0), "ramp_time"),
])
def test_bad_input_refused_in_one_line(make, arg):
    with pytest.raises(InputError) as exc:
        make()
    msg = str(exc.value)
    assert msg.startswith(f"{arg}=") and "\n" not in msg


def test_csv_with_unknown_columns_refused(tmp_path):
    for header in ("time,u\n0,1\n", "t_us,v_km_s\n0,1\n", "t_us,u_km_s,u_m_s\n0,1,2\n", "t_min,u_km_s\n0,1\n"):
        f = tmp_path / "bad.csv"
        f.write_text(header)
        with pytest.raises(InputError, match=r"^columns=.*t_s\|t_ms") as exc:
            Table.read_csv(f)
        assert "\n" not in str(exc.value)

"""Segment method and mesoscale friction (clusterdyn.mca.contact, scene mca-friction).

Small samples (a few dozen automata) so the whole file runs in well under a minute.
"""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build.mca import mca_packing
from clusterdyn.errors import InputError
from clusterdyn.materials import get_material
from clusterdyn.mca.contact import SegmentContact, stack_blocks
from clusterdyn.mca.dynamics import MCADynamics

D = 10 * units.um
MS = units.m_s


def _free_blocks(contact, L_lo=6, L_up=4, vx=20.0, vy=-3.0):
    """Two free (non-periodic) blocks, the upper sliding along x and pressed into the lower."""
    mat = get_material("alumina")
    lo = mca_packing(mat, D, (L_lo * D, 2 * D), packing="hex")
    up = mca_packing(mat, D, (L_up * D, 2 * D), packing="hex")
    atoms = stack_blocks([lo, up])
    body = atoms.arrays["body"]
    v = np.zeros((len(atoms), 3))
    v[body == 1, 0] = vx * MS
    v[body == 1, 1] = vy * MS
    atoms.set_velocities(v)
    return atoms, MCADynamics(atoms, contact=contact)


def _momenta(dyn):
    a = dyn.atoms
    p = a.get_momenta()
    x = a.positions
    L = float(np.sum(x[:, 0] * p[:, 1] - x[:, 1] * p[:, 0]) + np.sum(dyn.J * a.arrays["omega"][:, 2]))
    return p.sum(axis=0), L, float(np.abs(p).sum()), float(np.abs(x[:, :2]).max() * np.abs(p).sum())


def test_surface_segments_and_no_cross_pairs():
    atoms, dyn = _free_blocks(SegmentContact(mu1=0.0, friction=False), vx=0.0, vy=0.0)
    st = dyn.state
    body = atoms.arrays["body"]
    rows = st.rows(atoms.arrays["id"])
    assert np.all(body[rows[st.pid_p2[:, 0]]] == body[rows[st.pid_p2[:, 1]]])   # ordinary contact off
    g = dyn.contact.geo
    seg = g["segments"]
    y = atoms.positions[:, 1]
    t = atoms.positions[seg[:, 1], :2] - atoms.positions[seg[:, 0], :2]
    n = np.stack([-t[:, 1], t[:, 0]], axis=1) / np.linalg.norm(t, axis=1)[:, None]
    for b in (0, 1):
        yb = y[body == b]
        top = (body[seg[:, 0]] == b) & np.isclose(y[seg[:, 0]], yb.max()) & np.isclose(y[seg[:, 1]], yb.max())
        bot = (body[seg[:, 0]] == b) & np.isclose(y[seg[:, 0]], yb.min()) & np.isclose(y[seg[:, 1]], yb.min())
        nrow = int(np.sum(np.isclose(yb, yb.max())))
        assert top.sum() == nrow - 1 and bot.sum() == nrow - 1
        assert np.allclose(n[top], [0, 1]) and np.allclose(n[bot], [0, -1])
    # touching at h = h0: contacts found, no force
    assert g["nc"] > 0
    assert np.allclose(g["fn"], 0.0, atol=1e-9 * g["E"].max() * D)


def test_normal_force_is_gradient_of_contact_energy():
    atoms, dyn = _free_blocks(SegmentContact(mu1=0.0, friction=False), vx=0.0, vy=0.0)
    body = atoms.arrays["body"]
    atoms.positions[body == 1, 1] -= 0.08 * D          # press: every contact loaded
    atoms.positions[body == 1, 0] += 0.13 * D
    c, st = dyn.contact, dyn.state
    f = c.normal(atoms, st)
    assert c.geo["nc"] > 0 and np.all(c.geo["fn"] > 0)
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-9 * np.abs(f).max())
    x = atoms.positions
    assert abs(np.sum(x[:, 0] * f[:, 1] - x[:, 1] * f[:, 0])) < 1e-9 * np.abs(f).max() * np.abs(x).max()
    e = 1e-6 * D
    k, a = int(c.geo["k"][0]), int(c.geo["a"][0])
    for row in (k, a):
        for ax in (0, 1):
            x0 = atoms.positions.copy()
            atoms.positions[row, ax] += e
            c.normal(atoms, st)
            ep = c.geo["energy"]
            atoms.positions[:] = x0
            atoms.positions[row, ax] -= e
            c.normal(atoms, st)
            em = c.geo["energy"]
            atoms.positions[:] = x0
            assert -(ep - em) / (2 * e) == pytest.approx(f[row, ax], rel=1e-5, abs=1e-6 * np.abs(f).max())


def test_free_sliding_conserves_momenta_and_balances_energy():
    c = SegmentContact(mu0=2e-4 * units.MPa / MS, mu1=0.4, K_av=0.1, A1=0.5 * units.um, l1=2 * units.um,
                       d1=6 * units.um, v_reg=0.05 * MS, seed=3)
    atoms, dyn = _free_blocks(c)
    p0, L0, ps, Ls = _momenta(dyn)
    E0 = dyn.total_energy()
    loaded = 0
    for _ in range(36):
        dyn.run(1)
        loaded += c.geo["nc"] > 0 and c.geo["fn"].max() > 0
    p1, L1, _, _ = _momenta(dyn)
    assert np.all(np.abs(p1 - p0) < 1e-12 * ps)
    assert abs(L1 - L0) < 1e-12 * Ls
    assert loaded == 36                                   # the blocks stayed in contact
    lost = E0 - dyn.total_energy()
    print("E0", E0, "lost", lost, "friction work", c.friction_work, "clips", c.clips)
    assert c.friction_work > 0.002 * E0
    assert lost == pytest.approx(c.friction_work, rel=0.01)


def test_bad_input_refused_in_one_line():
    for kw in ({"mu0": -1.0}, {"mu1": -0.1}, {"K_av": -0.2}, {"A1": -1.0}, {"v_reg": 0.0}):
        with pytest.raises(InputError) as e:
            SegmentContact(**kw)
        assert "\n" not in str(e.value) and list(kw)[0] in str(e.value)
    mat = get_material("alumina")
    b3 = mca_packing(mat, D, (4 * D, 3 * D, 3 * D), packing="fcc")
    with pytest.raises(InputError) as e:
        stack_blocks([b3, b3.copy()])
    assert "2D" in str(e.value) and "\n" not in str(e.value)
    from clusterdyn.mca.calculator import MCA
    b3.calc = MCA()
    b3.new_array("body", (b3.positions[:, 1] > 1.5 * D).astype(np.int64))
    with pytest.raises(InputError) as e:
        MCADynamics(b3, contact=SegmentContact())
    assert "plane strain" in str(e.value) and "\n" not in str(e.value)
    from clusterdyn.scenes.base import get_scene
    sc = get_scene("mca-friction")
    for bad in ({"stress": "-0.05GPa"}, {"stress": "0GPa"}, {"mu1": "-0.3"}, {"mu0": "-1"}, {"K_av": "-0.1"}):
        with pytest.raises(InputError) as e:
            sc.run(bad, progress=False)
        assert "\n" not in str(e.value) and list(bad)[0] in str(e.value)


def _scene_mu(**kw):
    from clusterdyn.scenes.base import get_scene
    from clusterdyn.scenes.mca_friction import steady_mu
    sc = get_scene("mca-friction")
    v = sc.parse({"size": (8, 2), "steps": 1500, "frames": 60, "h5md": False, **kw})
    atoms, dyn, info = sc.setup(v, "main")
    stage = sc.attach(v, "main", atoms, dyn, info)
    from clusterdyn.scenes.common import run_frames
    run_frames(dyn, stage.nsteps, stage.frames, stage.on_frame, progress=False)
    return steady_mu(stage.analysis.get_state(), info["t_slide"], info["T"]), dyn


@pytest.mark.parametrize("mu1", [0.1, 0.3, 0.6])
def test_dry_friction_gives_mu1(mu1):
    (mu, sd, n), _ = _scene_mu(mu1=str(mu1))
    assert n >= 10
    assert mu == pytest.approx(mu1, rel=0.02)


def test_viscous_part_linear_in_speed():
    mu0 = 0.02            # MPa per m/s
    vals = []
    for V in (10.0, 20.0, 40.0):
        (mu, sd, n), dyn = _scene_mu(mu1="0", mu0=str(mu0), V=f"{V}m/s")
        vals.append(mu / V)
    vals = np.array(vals)
    st, body = dyn.state, dyn.atoms.arrays["body"]
    rows = st.rows(dyn.atoms.arrays["id"])
    assert np.all(body[rows[st.pid_p2[:, 0]]] == body[rows[st.pid_p2[:, 1]]])   # no ordinary contact across
    assert vals.min() > 0
    assert np.ptp(vals) < 0.03 * vals.mean()
    # slope against the law: mu_dr = mu0 V sum(r0) / F_N with every contact sliding at V
    g = dyn.contact.geo
    r0 = dyn.state.r0_p[g["p"]].sum()
    FN = 0.05 * units.GPa * dyn.atoms.cell[0, 0]
    assert vals.mean() == pytest.approx(mu0 * units.MPa / MS * r0 * MS / FN, rel=0.05)


def test_restart_bit_for_bit_with_friction_history(tmp_path):
    """2N steps = N + save_run/load_run + N, bit for bit, with live interlocking histories."""
    from clusterdyn.io.checkpoint import load_run, save_run
    from clusterdyn.scenes.base import get_scene
    sc = get_scene("mca-friction")
    v = sc.parse({"size": (6, 2), "steps": 400, "K_av": "0.2", "A1": "2um", "l1": "0.05um", "d1": "0.1um",
                  "A2": "0.5um", "l2": "0.02um", "d2": "0.05um", "v_reg": "0.05m/s", "seed": 7})
    atoms, dyn, info = sc.setup(v, "main")
    dyn.run(150)
    c = dyn.contact
    assert c.hist["active"].sum() > 0 and c.hist["ndraw"].sum() > c.hist["active"].sum()   # live history
    path = tmp_path / "ck.h5"
    save_run(path, dyn)
    dyn.run(150)
    a2, d2, _ = load_run(path)
    d2.run(150)
    assert c.clips[0] > 0
    assert np.array_equal(atoms.positions, a2.positions)
    assert np.array_equal(atoms.get_momenta(), a2.get_momenta())
    assert np.array_equal(atoms.arrays["omega"], a2.arrays["omega"])
    for k in c.hist:
        assert np.array_equal(c.hist[k], d2.contact.hist[k])
    assert c.friction_work == d2.contact.friction_work
    assert np.array_equal(c.clips, d2.contact.clips)
    tr = [x for x in atoms.constraints if hasattr(x, "friction")][0]
    tr2 = [x for x in a2.constraints if hasattr(x, "friction")][0]
    assert np.array_equal(tr.friction, tr2.friction)


def test_interlocking_sections_seeded_and_clipped():
    kw = dict(mu1=0.3, K_av=0.05, A1=3 * units.um, l1=0.05 * units.um, d1=0.2 * units.um, v_reg=0.05 * MS)
    runs = []
    for seed in (1, 1, 2):
        c = SegmentContact(seed=seed, **kw)
        atoms, dyn = _free_blocks(c, vy=-2.0)
        Ks = []
        for _ in range(80):
            dyn.run(1)
            Ks.append(c.last["K"].copy())
        runs.append((np.concatenate(Ks), c.clips[0]))
    assert np.array_equal(runs[0][0], runs[1][0])
    assert not np.array_equal(runs[0][0], runs[2][0])
    K = runs[0][0]
    assert K.min() == 0.0 and runs[0][1] > 0          # large amplitudes: clipped, and counted
    assert K.max() > kw["K_av"] + 0.5 * kw["A1"] / (0.5 * D)


def test_scene_restart_continues_bit_for_bit(tmp_path, monkeypatch):
    """The scene lifecycle: a run stopped at a checkpoint and continued with --restart ends as the whole run."""
    from clusterdyn.io.checkpoint import load_run
    from clusterdyn.scenes import mca_friction as mf
    from clusterdyn.scenes.base import get_scene
    sc = get_scene("mca-friction")
    kw = {"size": "6x2", "steps": 400, "frames": 40, "checkpoint_every": 3, "K_av": "0.1", "A1": "1um",
          "l1": "0.05um", "d1": "0.2um", "v_reg": "0.05m/s"}
    whole = sc.run(kw, out=tmp_path / "a", progress=False)
    orig = mf.FrictionScene.attach

    def stopping(self, v, stage, atoms, dyn, info):
        s = orig(self, v, stage, atoms, dyn, info)
        s.stop = lambda d: d.nsteps >= 200
        return s

    monkeypatch.setattr(mf.FrictionScene, "attach", stopping)
    sc.run(kw, out=tmp_path / "b", progress=False)     # stopped at step 200, last checkpoint before it
    monkeypatch.setattr(mf.FrictionScene, "attach", orig)
    cont = sc.run({}, out=tmp_path / "b", progress=False, restart=tmp_path / "b" / "checkpoint.h5")
    aA, dA, _ = load_run(tmp_path / "a" / "checkpoint.h5")
    aB, dB, _ = load_run(tmp_path / "b" / "checkpoint.h5")
    assert dA.nsteps == dB.nsteps > 200
    assert np.array_equal(aA.positions, aB.positions) and np.array_equal(aA.get_momenta(), aB.get_momenta())
    for k in dA.contact.hist:
        assert np.array_equal(dA.contact.hist[k], dB.contact.hist[k])
    assert dA.contact.clips[0] > 0
    assert whole.quantities["mu_dr"].value == cont.quantities["mu_dr"].value

"""LAMMPS export without LAMMPS: data file, tables, input script, CLI, the damping force law."""

import json
import re

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.cli import main as cli_main
from clusterdyn.errors import InputError
from clusterdyn.io.lammps import (aligned_points, export_lammps, initial_bond_pairs, lammps_table_forces,
                                  read_dump, table_grid, table_interpolation_error)
from clusterdyn.md.lammps_form import id_ranges
from clusterdyn.io.lammps.run import _parse_log
from clusterdyn.scenes.shock import build_shock

NPTS = 2001


@pytest.fixture(scope="module")
def shock():
    s = build_shock(size=(8, 3, 3), u=3 * units.km_s, J=50, seed=2)
    s.dyn.run(40)
    return s


@pytest.fixture(scope="module")
def deck(shock, tmp_path_factory):
    d = tmp_path_factory.mktemp("deck")
    export_lammps(shock.atoms, shock.calc, shock.dyn, d, nsteps=30, frames=3, n_points=NPTS)
    return d


def read_table(path, name):
    lines = path.read_text().split("\n")
    k = lines.index(name)
    head = lines[k + 1].split()
    n = int(head[1])
    rows = np.array([[float(x) for x in ln.split()] for ln in lines[k + 3:k + 3 + n]])
    return head, rows


def test_table_on_lammps_rsq_grid(shock, deck):
    head, rows = read_table(deck / "cd.table", "CD_1_1")
    t = shock.calc.tables[0][0]
    assert head[0] == "N" and int(head[1]) == NPTS and head[2] == "RSQ"
    r_lo, r_hi = float(head[3]), float(head[4])
    assert r_lo == t.r_min and r_hi == t.cutoff          # exact: LAMMPS' 'match' needs rhi == cutoff
    assert np.array_equal(rows[:, 0], np.arange(1, NPTS + 1))
    assert np.array_equal(rows[:, 1], table_grid(r_lo, r_hi, NPTS))
    e, f = t.evaluate(rows[:-1, 1])
    assert np.array_equal(rows[:-1, 2], e) and np.array_equal(rows[:-1, 3], f)
    assert rows[-1, 2] == 0.0 and rows[-1, 3] == t.f_cut  # shifted energy vanishes at the cutoff


def test_interpolation_bound_default_points(shock):
    """LAMMPS' linear-in-r^2 lookup of the exported table vs clusterdyn's cubic table."""
    err = table_interpolation_error(shock.calc)["CD_1_1"]
    # largest at 0.75 r0, the cold table's densest row, where the tail's slope jumps (a kink in f)
    assert err["max_rel_to_fmax_r_ge_0.75r0"] < 5e-6
    t = shock.calc.tables[0][0]
    # away from the kink, and relative to the local force down to the table's end (0.2 r0)
    r = np.linspace(0.76, 1.149, 20001) * t.law.r0
    _, f_l = lammps_table_forces(t, r)
    assert np.abs(f_l - t.evaluate(r)[1]).max() < 1e-8 * err["fmax_r_ge_0.75r0"]
    r = np.linspace(t.r_min, 0.7 * t.law.r0, 20001)
    f = t.evaluate(r)[1]
    assert np.max(np.abs(lammps_table_forces(t, r)[1] - f) / np.abs(f)) < 1e-6
    r = np.array([0.8, 0.95, 1.0, 1.05, 1.149]) * t.law.r0
    e_l, f_l = lammps_table_forces(t, r)
    e, f = t.evaluate(r)
    assert np.allclose(f_l, f, rtol=0, atol=1e-8 * np.abs(f).max())


def test_data_file(shock, deck):
    text = (deck / "data.cd").read_text()
    a = shock.atoms
    assert f"{len(a)} atoms" in text and "1 atom types" in text
    m = float(re.search(r"Masses\n\n1 (\S+)", text).group(1))
    assert m == a.get_masses()[0]
    body = text.split("Atoms # atomic\n\n")[1].split("\n\nVelocities")[0].split("\n")
    xyz = np.array([[float(x) for x in ln.split()[2:]] for ln in body])
    L = np.diag(a.cell.array)
    d = xyz - a.positions
    assert np.allclose(d[:, 0], 0.0, atol=1e-9 * L[1])                  # open along x
    assert np.allclose(np.round(d[:, 1:] / L[1:]) * L[1:], d[:, 1:], atol=1e-6)   # wrapped across
    vel = np.array([[float(x) for x in ln.split()[1:]]
                    for ln in text.split("Velocities\n\n")[1].strip().split("\n")])
    assert np.allclose(vel, a.get_velocities() * units.PS, rtol=1e-14)
    # 3 km/s is 30 Angstrom/ps
    assert np.isclose(vel.max(), 30.0, rtol=0.05)


def test_input_script(shock, deck):
    text = (deck / "in.cd").read_text()
    c = shock.calc
    p = c.potentials[0]
    assert "units           metal" in text and "boundary        s p p" in text
    assert f"pair_style      hybrid/overlay table linear {NPTS} dpd/ext/tstat 0.0 0.0" in text
    g = re.search(r"pair_coeff\s+1 1 dpd/ext/tstat (\S+) (\S+) 0.0 0.0 (\S+)", text)
    assert g, text
    gamma = float(g.group(1))
    assert float(g.group(2)) == gamma
    # gamma = m Gamma = m c0/(J r0), in eV ps/Angstrom^2
    m_gamma = p.mass * p.c0 / (50 * p.r0)
    assert np.isclose(gamma, m_gamma / units.PS, rtol=1e-12)
    assert float(g.group(3)) == c.tables[0][0].cutoff
    assert "comm_modify     vel yes" in text
    mv = re.search(r"fix\s+move_piston0 piston0 move linear (\S+) (\S+) (\S+)", text)
    assert np.isclose(float(mv.group(1)), 30.0, rtol=1e-12)
    assert "fix             integrate mobile nve" in text
    dt = float(re.search(r"timestep\s+(\S+)", text).group(1))
    assert np.isclose(dt, shock.dyn.dt / units.PS, rtol=1e-14)
    ids = [int(x) for grp in re.findall(r"group piston0 id (.*)", text) for x in
           sum([list(range(int(r.split(":")[0]), int(r.split(":")[-1]) + 1)) for r in grp.split()], [])]
    assert sorted(ids) == sorted((shock.piston.index + 1).tolist())
    meta = json.loads((deck / "cd.json").read_text())
    assert meta["nsteps"] == 30 and meta["J"] == 50 and meta["n_particles"] == len(shock.atoms)


def test_undamped_script_has_no_dpd(tmp_path):
    s = build_shock(size=(6, 3, 3), J=None)
    export_lammps(s.atoms, s.calc, s.dyn, tmp_path, n_points=101)
    text = (tmp_path / "in.cd").read_text()
    assert "dpd" not in text and "pair_style      table linear 101" in text
    assert "pair_coeff      1 1 cd.table CD_1_1" in text


def test_dpd_ext_tstat_at_zero_temperature_is_pair_damping():
    """dpd/ext/tstat's dissipative force with w = 1 (exponent 0) and gamma_par = gamma_perp = g:
    -g (rhat.v) rhat - g (1 - rhat rhat) v = -g v, the CD eq. (6) pair force."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        rhat = rng.normal(size=3)
        rhat /= np.linalg.norm(rhat)
        v = rng.normal(size=3)
        g = rng.uniform(0.1, 10)
        w = (1 - 0.7) ** 0.0
        par = -g * w * w * (rhat @ v) * rhat
        perp = -g * w * w * (v - (rhat @ v) * rhat)
        assert np.allclose(par + perp, -g * v)


def test_cli_export(tmp_path):
    out = tmp_path / "deck"
    assert cli_main(["export", "lammps", "shock", "--set", "size=10x3x3", "--set", "u=2km/s",
                     "--set", "J=50", "--quiet", "--out", str(out)]) == 0
    for f in ("data.cd", "cd.table", "in.cd", "cd.json"):
        assert (out / f).exists()
    meta = json.loads((out / "cd.json").read_text())
    assert meta["extra"]["scene"] == "shock" and meta["nsteps"] > 100 and meta["J"] == 50
    assert cli_main(["export", "lammps", "nosuchscene", "--out", str(out)]) == 2


def test_ranges_and_parsers(tmp_path):
    assert id_ranges([5, 1, 2, 3, 7, 8]) == ["1:3", "5", "7:8"]
    dump = tmp_path / "d.dump"
    dump.write_text("ITEM: TIMESTEP\n7\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS ss pp pp\n0 1\n0 1\n0 1\n"
                    "ITEM: ATOMS id type x y z vx vy vz fx fy fz\n2 1 1 2 3 4 5 6 7 8 9\n1 1 0 0 0 0 0 0 0 0 1\n")
    fr = read_dump(dump)
    assert fr[0]["step"] == 7 and fr[0]["id"].tolist() == [1, 2] and fr[0]["forces"][1, 2] == 9
    log = ("   Step          Time          PotEng         KinEng         TotEng    \n"
           "         0   0   -1   2   1\n        10   0.5  -1.5   2.5   1\n"
           "Loop time of 1.5 on 2 procs for 10 steps with 100 atoms\n\nNeighbor list builds = 3\n")
    loop, thermo, builds = _parse_log("\n" + log)
    assert loop[-1] == ("1.5", "2", "10", "100") and builds == 3 and thermo[1][2] == -1.5


def test_drive_fixes_in_the_deck(tmp_path):
    """A wall becomes a plane region + fix wall/region harmonic with the wall's own K and d_c; a U(t)
    table piston becomes fix move variable; refusals name the drive and write nothing."""
    from clusterdyn.errors import InputError
    from clusterdyn.md import DampedVerlet, Piston, Table, Traction, Wall
    s = build_shock(size=(8, 3, 3), u=3 * units.km_s, J=None, seed=2)
    a = s.atoms
    x_max = a.positions[:, 0].max()
    w = Wall([x_max + 0.55 * s.calc.potentials[0].r0, 0, 0], [-1.0, 0.0, 0.0])
    p = Piston(s.piston.index, Table([0.0, 1 * units.ns], [0.0, 3 * units.km_s]))
    a.set_constraint([p, w])
    dyn = DampedVerlet(a, timestep=s.dyn.dt, J=None)
    export_lammps(a, s.calc, dyn, tmp_path / "ok", nsteps=10, frames=1)
    text = (tmp_path / "ok" / "in.cd").read_text()
    K, dc = w.resolve(a)
    assert f"region          wall1 plane {float(w.point[0])!r} 0.0 0.0 -1.0 0.0 0.0 side in units box" in text
    assert f"fix             wall1 all wall/region wall1 harmonic {float(K[0])!r} 1.0 {float(dc[0])!r}" in text
    assert "fix_modify      wall1 energy yes" in text
    assert re.search(r"fix\s+move_piston0 piston0 move variable v_piston0_dx v_piston0_dy v_piston0_dz "
                     r"v_piston0_vx v_piston0_vy v_piston0_vz", text)
    assert "max(" not in text
    meta = json.loads((tmp_path / "ok" / "cd.json").read_text())
    assert meta["groups"]["wall1"]["K_eV_per_A2"] == [K[0]] and meta["groups"]["piston0"]["law"] == "table"
    bad = [
        ([Traction(s.piston.index, [-1, 0, 0], 1e-3, velocity=[0.0, 1e-3, 0.0], area=1.0)], "tangential"),
        ([Traction(s.piston.index, [-0.6, 0.8, 0], 1e-3, area=1.0)], "along x, y or z"),
        ([Wall([0, 0, 0], [1, 0, 0], sticking=True)], "sticking"),
        ([Piston(s.piston.index, lambda t: 1.0)], "callable"),
        ([Wall([0, 0, 0], [0, 1, 0])], "periodic"),
    ]
    tr = Traction(s.piston.index, [-1, 0, 0], Table([0.0, 1 * units.ns], [0.0, 2e-3]), area=4.0)
    a.set_constraint(tr)
    export_lammps(a, s.calc, DampedVerlet(a, timestep=s.dyn.dt, J=None), tmp_path / "tr", nsteps=10, frames=1)
    text = (tmp_path / "tr" / "in.cd").read_text()
    assert "fix             ave_traction0 traction0 aveforce v_traction0_f NULL NULL" in text
    assert "fix             tan_traction0 traction0 setforce NULL 0.0 0.0" in text
    assert "fix             integrate all nve" in text                  # the layer is integrated, not moved
    for cons, word in bad:
        a.set_constraint(cons)
        with pytest.raises(InputError, match=f"^atoms.constraints=.*{word}") as exc:
            export_lammps(a, s.calc, dyn, tmp_path / word, nsteps=10)
        assert "\n" not in str(exc.value) and not (tmp_path / word).exists()


# -- two materials, set-up bonds (attraction="initial"), scene settings --------------------------

def two_phase_initial(J=50.0):
    """A small Al block with B4C spheres, attraction='initial' (the issue's example, small)."""
    return build_shock(size=(10, 4, 4), u=2 * units.km_s, J=J, seed=4, inclusion="B4C",
                       inclusion_diameter=20 * units.um, attraction="initial")


def test_initial_two_material_deck(tmp_path):
    """Two atom types with their masses, the set-up bonds as LAMMPS bonds, the law and the remainder tables
    on one grid (r0_ab^2 a node), per-sub-style special weights, three dpd sub-styles."""
    s = two_phase_initial()
    a, c = s.atoms, s.calc
    export_lammps(a, c, s.dyn, tmp_path, nsteps=10, frames=1, n_points=NPTS)
    data = (tmp_path / "data.cd").read_text()
    mat = a.arrays["material"]
    assert "2 atom types" in data and "Atoms # bond" in data
    masses = re.search(r"Masses\n\n1 (\S+)\n2 (\S+)\n", data)
    m = a.get_masses()
    assert float(masses.group(1)) == m[mat == 0][0] and float(masses.group(2)) == m[mat == 1][0]
    body = data.split("Atoms # bond\n\n")[1].split("\n\nVelocities")[0].split("\n")
    assert [int(ln.split()[2]) for ln in body] == (mat + 1).tolist()
    # bonds: every pair listed in bonds0, once, as ids = rows + 1
    nb = int(re.search(r"(\d+) bonds", data).group(1))
    bonds = np.array([[int(x) for x in ln.split()[2:]] for ln in data.split("Bonds\n\n")[1].strip().split("\n")])
    b0 = a.arrays["bonds0"]
    assert nb == len(bonds) == (b0 >= 0).sum() // 2 and np.all(bonds[:, 0] < bonds[:, 1])
    row = {int(i): k for k, i in enumerate(a.arrays["id"])}
    listed = {(min(k, row[int(j)]), max(k, row[int(j)])) for k in range(len(a)) for j in b0[k] if j >= 0}
    assert listed == {(i - 1, j - 1) for i, j in bonds.tolist()}
    text = (tmp_path / "in.cd").read_text()
    N = aligned_points(c, NPTS)
    assert (N - 1) % c.tables[0][0].n_bins == 0 and N >= NPTS
    for line in ("atom_style      bond", "bond_style      zero", "special_bonds   lj/coul 0.5 1.0 1.0",
                 "pair_modify     pair table 1 special lj 1.0 1.0 1.0",
                 "pair_modify     pair table 2 special lj 0.0 1.0 1.0",
                 "pair_modify     pair dpd/ext/tstat 2 special lj 0.0 1.0 1.0",
                 "pair_modify     pair dpd/ext/tstat 3 special lj 0.0 1.0 1.0",
                 "pair_coeff      1 2 table 2 cd.table CDR_1_2",
                 f"pair_style      hybrid/overlay table linear {N} table linear {N} dpd/ext/tstat"):
        assert line in text, line
    assert "lost/bond ignore" in text
    eta = c.damping_matrix(50.0)[0, 1] / units.PS
    t01 = c.tables[0][1]
    g1 = re.search(r"pair_coeff\s+1 2 dpd/ext/tstat 1 (\S+) (\S+) 0.0 0.0 (\S+)", text)
    g2 = re.search(r"pair_coeff\s+1 2 dpd/ext/tstat 2 (\S+) (\S+) 0.0 0.0 (\S+)", text)
    g3 = re.search(r"pair_coeff\s+1 2 dpd/ext/tstat 3 (\S+) (\S+) 0.0 0.0 (\S+)", text)
    assert np.isclose(float(g1.group(1)), eta, rtol=1e-12) and float(g2.group(1)) == -float(g1.group(1))
    assert float(g1.group(3)) == t01.cutoff == float(g2.group(3)) and float(g3.group(3)) == t01.law.r0
    # the remainder: E(cutoff) shift and no force below r0_ab, minus the law from r0_ab on, same grid
    for a_, b_ in ((0, 0), (0, 1), (1, 1)):
        t = c.tables[a_][b_]
        _, full = read_table(tmp_path / "cd.table", f"CD_{a_ + 1}_{b_ + 1}")
        head, rem = read_table(tmp_path / "cd.table", f"CDR_{a_ + 1}_{b_ + 1}")
        assert int(head[1]) == N and np.array_equal(rem[:, 1], full[:, 1])
        inside = rem[:, 1] ** 2 < t.law.r0 ** 2
        assert np.all(rem[inside, 3] == 0.0) and np.all(rem[inside, 2] == t.e_shift)
        assert np.array_equal(rem[~inside, 2:], -full[~inside, 2:])
        k0 = np.argmin(np.abs(rem[:, 1] - t.law.r0))           # r0_ab sits on the grid
        assert abs(rem[k0, 1] / t.law.r0 - 1) < 1e-14
    meta = json.loads((tmp_path / "cd.json").read_text())
    assert meta["attraction"] == "initial" and meta["n_bonds"] == nb and meta["n_types"] == 2


def test_one_sided_bonds_refused(tmp_path):
    s = two_phase_initial(J=None)
    a = s.atoms
    b = a.arrays["bonds0"].copy()
    k = int(np.argmax((b >= 0).sum(axis=1)))
    n = int((b[k] >= 0).sum())
    b[k, n - 1] = -1                                   # k forgets its last partner, which still lists k
    a.arrays["bonds0"] = b
    with pytest.raises(InputError, match=r"^atoms.arrays\['bonds0'\]=.*1 one-sided") as exc:
        export_lammps(a, s.calc, s.dyn, tmp_path / "deck")
    assert "\n" not in str(exc.value) and not (tmp_path / "deck").exists()
    b[k, n - 1] = a.arrays["id"][k]                    # bonded to itself
    a.arrays["bonds0"] = b
    with pytest.raises(InputError, match="bonded to itself"):
        initial_bond_pairs(a, s.calc)


def test_cli_issue_example(tmp_path, capsys):
    """``export lammps shock --set attraction=initial --set inclusion=B4C`` (smaller): a two-type deck with
    the set-up bonds, and cd.json's settings are the deck's."""
    out = tmp_path / "deck"
    assert cli_main(["export", "lammps", "shock", "--set", "attraction=initial", "--set", "inclusion=B4C",
                     "--set", "size=10x4x4", "--set", "inclusion_diameter=20um", "--out", str(out)]) == 0
    assert f"wrote LAMMPS deck to {out}" in capsys.readouterr().out
    data = (out / "data.cd").read_text()
    text = (out / "in.cd").read_text()
    meta = json.loads((out / "cd.json").read_text())
    assert "2 atom types" in data and int(re.search(r"(\d+) bonds", data).group(1)) > 0
    assert "pair_coeff      1 2 table 2 cd.table CDR_1_2" in text
    p = meta["extra"]["params"]
    assert p["attraction"] == meta["attraction"] == "initial" and p["inclusion"] == "B4C" and meta["n_types"] == 2
    assert meta["extra"]["stage_info"]["two_phase"]["inclusion"] == "B4C"
    assert set(meta["extra"]["not_in_deck"]) == {"h5md", "h5md_frames", "checkpoint_every", "dt_retries"}


def test_cli_shock_settings_in_the_deck(tmp_path):
    """axis, u_history (fix move variable), J, rc, dt_factor, frames reach the deck."""
    csv = tmp_path / "u.csv"
    csv.write_text("t_ns,u_km_s\n0,0\n1,2\n2,1.5\n")
    out = tmp_path / "deck"
    assert cli_main(["export", "lammps", "shock", "--set", "size=10x3x3", "--set", "axis=z",
                     "--set", f"u_history={csv}",
                     "--set", "u=2km/s", "--set", "J=40", "--set", "rc=1.2", "--set", "dt_factor=0.02",
                     "--set", "frames=7", "--set", "dt_retries=0", "--set", "checkpoint_every=0",
                     "--set", "h5md=false", "--quiet", "--out", str(out)]) == 0
    text = (out / "in.cd").read_text()
    meta = json.loads((out / "cd.json").read_text())
    assert "boundary        p p s" in text
    assert re.search(r"fix\s+move_piston0 piston0 move variable", text)
    assert meta["groups"]["piston0"]["law"] == "table"
    v = np.array(meta["groups"]["piston0"]["velocity_A_per_ps"])
    assert np.allclose(v[:, :2], 0) and np.allclose(v[:, 2], [0.0, 20.0, 15.0])       # along z, km/s -> A/ps
    assert np.allclose(meta["groups"]["piston0"]["t_ps"], [0.0, 1000.0, 2000.0])
    r0 = 5 * units.um
    assert np.isclose(meta["cutoff_A"], 1.2 * r0) and meta["J"] == 40 and meta["extra"]["axis"] == 2
    s = build_shock(size=(10, 3, 3), u=2 * units.km_s, rc=1.2, dt_factor=0.02, axis="z", u_history=str(csv))
    assert meta["dt_ase"] == s.dyn.dt and meta["nsteps"] == s.nsteps and meta["dump_every"] == s.nsteps // 7
    assert meta["extra"]["not_in_deck"] == {"h5md_frames": meta["extra"]["not_in_deck"]["h5md_frames"]}


def test_plate_impact_decks(tmp_path):
    """plate-impact with sample=both: one deck per stage (single, polycrystal with set-up bonds inside grains)."""
    out = tmp_path / "pi"
    assert cli_main(["export", "lammps", "plate-impact", "--set", "flyer=4", "--set", "target=6", "--set", "width=3",
                     "--set", "relax_cycles=0", "--set", "grain_size=3", "--set", "boundaries=repulsive",
                     "--quiet", "--out", str(out)]) == 0
    single = json.loads((out / "single" / "cd.json").read_text())
    poly = json.loads((out / "polycrystal" / "cd.json").read_text())
    assert single["attraction"] == "all" and poly["attraction"] == "initial" and poly["n_bonds"] > 0
    assert single["J"] == 50 and single["extra"]["stage"] == "single" and single["nsteps"] > 0
    assert "not_in_deck" in poly["extra"] and "profile_times" in poly["extra"]["not_in_deck"]


@pytest.mark.parametrize("args, word", [
    (["mca-tension"], "scene='mca-tension'.*MCA"),
    (["shock", "--set", "h5md_frames=5"], "h5md_frames='5'"),
    (["shock", "--set", "h5md=true"], "h5md='true'.*H5MD"),
    (["shock", "--set", "checkpoint_every=3"], "checkpoint_every='3'"),
    (["shock", "--set", "dt_retries=1"], "dt_retries='1'.*half the time step"),
    (["plate-impact", "--set", "profile_times=1,2"], "profile_times='1,2'"),
    (["shock", "--set", "u=1km/s", "--set", "u_history=U_CSV"], "u_history=.*no faster than u = 1 km/s"),
    (["shock", "--set", "u_history=NO_FILE"], "u_history=.*CSV"),
    (["shock", "--set", "size=6x3x3"], "size='6x3x3'"),
])
def test_cli_refusals(tmp_path, capsys, args, word):
    """Each setting a deck cannot carry is refused in one line naming it, exit 2, nothing written."""
    csv = tmp_path / "u.csv"
    csv.write_text("t_ns,u_km_s\n0,0\n1,2\n")
    args = [x.replace("U_CSV", str(csv)).replace("NO_FILE", str(tmp_path / "none.csv")) for x in args]
    out = tmp_path / "deck"
    assert cli_main(["export", "lammps"] + args + ["--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.split("\n")) == 1 and re.search(word, err), err
    assert not out.exists()


def test_every_drive_writes_or_refuses_its_own_form(tmp_path):
    """The exporter asks each constraint for its LAMMPS form: a drive class without one (the base's) and a
    region of interest are refused in one line naming them, before any file."""
    from clusterdyn.errors import InputError
    from clusterdyn.md import DampedVerlet, Drive, RegionOfInterest
    s = build_shock(size=(8, 3, 3), u=3 * units.km_s, J=None, seed=2)

    class Pusher(Drive):
        kind = "Pusher"

    s.atoms.set_constraint([s.piston, Pusher()])
    with pytest.raises(InputError, match=r"^atoms.constraints=.*Pusher has none"):
        export_lammps(s.atoms, s.calc, s.dyn, tmp_path / "pusher", nsteps=10)
    s.atoms.set_constraint(s.piston)
    dyn = DampedVerlet(s.atoms, timestep=s.dyn.dt, J=None, region=RegionOfInterest(hi=[1e9, np.inf, np.inf]))
    with pytest.raises(InputError, match=r"^region=.*no region of interest") as exc:
        export_lammps(s.atoms, s.calc, dyn, tmp_path / "region", nsteps=10)
    assert "\n" not in str(exc.value)
    assert not (tmp_path / "pusher").exists() and not (tmp_path / "region").exists()
    assert Drive._KINDS.pop("Pusher") is Pusher


def test_continuation_runs_resume_the_removal_loop():
    """The runs of a continuation from a restart step (the deck text; run by LAMMPS in
    tests/io/test_lammps_engine.py::test_resume_from_restart_file): no region, ``run N upto``; with the
    removal every 10 of 1015 steps, from within a block ``upto`` its end and its deletion, from a block's
    end that block's deletion first (the restart file holds the state before it), in the last partial
    block ``upto`` the end; the loop then counts the blocks left."""
    from clusterdyn.io.lammps.export import _run_lines, run_boundaries
    assert _run_lines(647) == ["run             647"]
    assert _run_lines(647, start=320) == ["run             647 upto"]
    first = _run_lines(1015, 10)
    assert first[:3] == ["variable        cdblock loop 101", "label           cdremove", "run             10"]
    assert first[-1] == "run             5"
    mid = _run_lines(1015, 10, start=255)
    assert mid[:3] == ["run             260 upto", "delete_atoms    group gone compress no",
                       "variable        cdblock loop 75"] and mid[-1] == "run             5"
    end = _run_lines(1015, 10, start=170, bonds=True)
    assert end[2] == "delete_atoms    group cdgone_now compress no bond yes"
    assert "intersect cdout_now removable" in end[1] and end[3] == "variable        cdblock loop 84"
    assert _run_lines(1015, 10, start=1010, bonds=True) == end[:3] + ["run             5"]
    assert _run_lines(1015, 10, start=1012) == ["run             1015 upto"]
    assert _run_lines(1010, 10, start=1010, bonds=True) == end[:3]
    assert run_boundaries(1015, 10)[-1] == 1010 and run_boundaries(647) == [0]

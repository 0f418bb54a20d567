"""Uniaxial tension / compression of an MCA bar between two grips (shared by scenes, tests and studies).

The bar lies along x; one layer of automata at each end is a grip: a
:class:`~clusterdyn.md.Piston` along x with ``lateral="free"`` (the automata
of a grip move freely across x, so the bar contracts or bulges at its ends
as in a test with lubricated platens) whose speed ``+-v/2`` rises over the
first ``ramp`` of the run as a :class:`~clusterdyn.md.SmoothRamp` (half
cosine, then constant) or follows a load path; the grip automata do not
rotate (``MCADynamics(hold_layer_rotation=True)``); pairs within 1.2 d of a
grip do not break (glued grips, so the crack forms in the gauge section).

Measured on every frame (:class:`UniaxialCurve`): engineering strain = change
of the distance between the grips' mean x / initial distance; engineering
stress = mean of the two grips' reactions along x (their recorded
:attr:`~clusterdyn.md.Piston.force`, pair damping included) / cross-section
(tension positive; 2D: per unit thickness).

:func:`build_uniaxial` makes the sample, grips and dynamics; :func:`uniaxial`
runs it in the scenes' frame loop (:func:`~clusterdyn.scenes.common.run_frames`)
and returns the curve; the ``mca-tension`` and ``mca-compression`` scenes run the
same set-up through the scene lifecycle (checkpoints, restart, H5MD).
"""

from dataclasses import dataclass

import numpy as np

from ..build.mca import mca_packing
from ..errors import InputError
from ..mca.calculator import MCA
from ..mca.dynamics import MCADynamics, wave_speeds
from ..md.histories import Function, SmoothRamp
from ..md.layer_drives import Piston
from .common import run_frames


def broken_links(state, npairs0):
    """Per automaton (state rows), the number of its set-up links now unlinked."""
    lk = state.linked_p[:npairs0] == 0
    ids = state.pid_p2[:npairs0][lk].ravel()
    rows = state.rows(state.id_n)
    return np.bincount(rows[ids], minlength=len(state.id_n))


@dataclass
class UniaxialSetup:
    """A built uniaxial test (ASE units)."""

    atoms: object
    dyn: object
    grips: tuple            #: (low, high) Piston drives
    L0: float               #: initial distance between the grips' mean x, Angstrom
    area: float             #: cross-section, Angstrom^2 (2D: width x unit thickness)
    sign: float             #: +1 tension, -1 compression
    reference: float        #: strength compared with (sigma_t, sigma_c or sigma_y)
    npairs0: int            #: pairs at set-up (later ones are contacts)
    steps: int
    strain_max: float


def build_uniaxial(material, mode="tension", d=1.0, size=(16, 5, 5), packing="fcc", strain_max=None,
                   steps=3000, ramp=0.1, damping=0.05, scatter=0.0, seed=0, path=None, pbc_lateral=False,
                   prepare=None):
    """Sample, grips and dynamics of a uniaxial test (see the module docstring).

    Parameters
    ----------
    material : Material
    mode : "tension" | "compression"
    d : automaton size, Angstrom; size : bar (Lx, Ly, Lz) in units of d (2D: (Lx, Ly))
    strain_max : final nominal strain (default 2.5 x the strength / E)
    steps : number of steps to strain_max; ramp : fraction of them spent ramping up
    damping : fraction of critical damping of relative pair velocity (quasi-static)
    scatter : relative scatter of pair strengths (uniform +-scatter, seeded); 0 = none
    path : optional callable ``f(s) -> strain`` of the load fraction ``s`` in [0, 1]
        (for unload/reload cycles; a callable history, so such a run has no checkpoints);
        default: a smooth ramp of the speed over ``ramp``, then constant
    prepare : optional callable ``f(atoms)`` run on the sample before the MCA state is
        built (pre-cracks, material ids)

    Returns
    -------
    UniaxialSetup
    """
    if mode not in ("tension", "compression"):
        raise InputError("mode", mode, "'tension' or 'compression'")
    sign = 1.0 if mode == "tension" else -1.0
    shape = tuple(float(s) * d for s in size)
    pbc = (False, pbc_lateral, pbc_lateral) if len(size) == 3 else (False, pbc_lateral, False)
    atoms = mca_packing(material, d, shape, packing, pbc=pbc, seed=seed)
    if prepare is not None:
        prepare(atoms)
    atoms.calc = MCA()
    st = atoms.calc.setup(atoms)
    if scatter > 0:
        rng = np.random.default_rng(seed)
        f = 1.0 + scatter * (2.0 * rng.random(st.npairs) - 1.0)
        st.sigc_p *= f
    npairs0 = st.npairs
    x = atoms.positions[:, 0]
    lo = x < x.min() + 0.3 * d
    hi = x > x.max() - 0.3 * d
    L0 = x[hi].mean() - x[lo].mean()
    # the grips are glued: pairs within two layers of a grip never break (cracks form in the gauge)
    near = (x < x.min() + 1.2 * d) | (x > x.max() - 1.2 * d)
    i_p, j_p = st.pair_rows(atoms)[:2]
    st.sigc_p[near[i_p] | near[j_p]] = 0.0
    ref = material.sigma_t if mode == "tension" else material.sigma_c
    if ref is None:
        ref = material.sigma_y
    if strain_max is None:
        strain_max = 2.5 * ref / material.E
    dt = MCADynamics(atoms, damping=damping).dt
    T = steps * dt
    t_r = ramp * T
    if path is None:
        # the grip distance grows by strain_max L0 over T: speed ramps up over t_r, then constant
        v_end = strain_max * L0 / (T - 0.5 * t_r)
        u_lo, u_hi = SmoothRamp(-0.5 * sign * v_end, t_r), SmoothRamp(0.5 * sign * v_end, t_r)
    else:
        h = 1e-4

        def vel(t):
            s = t / T
            return (path(min(s + h, 1.0)) - path(max(s - h, 0.0))) / (2 * h * T) * strain_max * L0 \
                if 0 <= s <= 1 else 0.0
        u_lo, u_hi = Function(lambda t: -0.5 * sign * vel(t)), Function(lambda t: 0.5 * sign * vel(t))
    g_lo = Piston(lo, u_lo, direction=(1.0, 0.0, 0.0), lateral="free")
    g_hi = Piston(hi, u_hi, direction=(1.0, 0.0, 0.0), lateral="free")
    atoms.set_constraint([g_lo, g_hi])
    dyn = MCADynamics(atoms, damping=damping, hold_layer_rotation=True)
    return UniaxialSetup(atoms, dyn, (g_lo, g_hi), float(L0), _area(atoms, size), sign, ref, npairs0, int(steps),
                         float(strain_max))


class UniaxialCurve:
    """The stress-strain curve of a uniaxial test, sampled by :meth:`add` (an analysis frame).

    Parameters
    ----------
    L0, area, sign :
        As in :class:`UniaxialSetup`.
    lo, hi : (M,) int arrays
        Rows of the two grips.
    """

    def __init__(self, L0, area, sign, lo, hi):
        self.L0, self.area, self.sign = float(L0), float(area), float(sign)
        self.lo, self.hi = np.asarray(lo, np.int64), np.asarray(hi, np.int64)
        self.time, self.strain, self.stress = [], [], []

    @classmethod
    def of(cls, setup):
        lo, hi = setup.grips
        return cls(setup.L0, setup.area, setup.sign, lo.index, hi.index)

    def add(self, dyn):
        """Sample the curve now: strain from the grips' positions, stress from their recorded forces."""
        x = dyn.atoms.positions[:, 0]
        grips = [c for c in dyn.atoms.constraints if isinstance(c, Piston)]
        f_lo, f_hi = grips[0].force[0], grips[1].force[0]
        e = (x[self.hi].mean() - x[self.lo].mean() - self.L0) / self.L0
        s = 0.5 * (f_lo - f_hi) / self.area          # mean reaction: the sample pulls the grips inward
        self.time.append(float(dyn.state.time))
        self.strain.append(float(self.sign * e))
        self.stress.append(float(self.sign * s))

    def arrays(self):
        """(time, strain, stress) arrays; time in ASE units, stress in eV/Angstrom^3."""
        return np.array(self.time), np.array(self.strain), np.array(self.stress)

    def peak(self):
        """(peak stress, strain at the peak)."""
        _, e, s = self.arrays()
        k = int(np.argmax(s))
        return float(s[k]), float(e[k])

    def get_state(self):
        return {"time": list(self.time), "strain": list(self.strain), "stress": list(self.stress)}

    def set_state(self, d):
        self.time, self.strain, self.stress = (list(map(float, d[k])) for k in ("time", "strain", "stress"))

    @classmethod
    def from_state(cls, d):
        """A curve with the samples of :meth:`get_state` (for analysis; it samples no more)."""
        c = cls(1.0, 1.0, 1.0, [], [])
        c.set_state(d)
        return c


def uniaxial(material, mode="tension", d=1.0, size=(16, 5, 5), packing="fcc", strain_max=None,
             steps=3000, ramp=0.1, damping=0.05, scatter=0.0, seed=0, path=None,
             interval=20, progress=False, observers=(), pbc_lateral=False,
             h5md=None, frames=20, prepare=None):
    """Drive a bar in tension or compression; return a dict with the curve and the run objects.

    The set-up is :func:`build_uniaxial` (its parameters); the curve is sampled
    every ``interval`` steps by :class:`UniaxialCurve` in the frame loop
    :func:`~clusterdyn.scenes.common.run_frames`.  ``observers`` are
    ``(callable, interval)`` pairs attached to the dynamics; ``h5md`` a path
    for a trajectory of ``frames`` frames with per-automaton stress, link and
    broken-link counts and the linked pairs.
    """
    s = build_uniaxial(material, mode, d, size, packing, strain_max, steps, ramp, damping, scatter, seed,
                       path, pbc_lateral, prepare)
    atoms, dyn = s.atoms, s.dyn
    for obs, n in observers:
        dyn.attach(obs, interval=n)
    writer = None
    if h5md is not None:
        from ..io import H5MDWriter
        writer = H5MDWriter(str(h5md), atoms, dyn=dyn, per_particle=uniaxial_per_particle(dyn, s.npairs0))
        dyn.attach(writer, interval=max(1, steps // frames))
    curve = UniaxialCurve.of(s)
    try:
        run_frames(dyn, steps, max(1, steps // max(1, int(interval))), curve.add, progress=progress,
                   desc=f"mca-{mode}")
    finally:
        if writer is not None:
            writer.close()
    t, strain, stress = curve.arrays()
    k = int(np.argmax(stress))
    return {"strain": strain, "stress": stress, "time": t, "peak_stress": stress[k],
            "strain_at_peak": strain[k], "atoms": atoms, "dyn": dyn, "npairs0": s.npairs0,
            "reference": s.reference, "area": s.area, "L0": s.L0, "wave_speeds": wave_speeds(material),
            "h5md_path": h5md, "setup": s}


def uniaxial_per_particle(dyn, npairs0):
    """H5MD per-automaton data of a uniaxial run: stress tensor (Voigt), broken set-up links, links."""
    return {"mca_stress": lambda a: a.calc.get_property("automaton_stresses", a),
            "broken_links": lambda a: broken_links(dyn.state, npairs0)[dyn.state.pair_rows(a)[5]],
            "links": lambda a: _links(dyn.state, a)}


def _links(state, atoms):
    """Linked pairs per automaton (rows of ``atoms``)."""
    i_p, j_p = state.pair_rows(atoms)[:2]
    lk = state.linked_p == 1
    return np.bincount(np.concatenate([i_p[lk], j_p[lk]]), minlength=len(atoms))


def _area(atoms, size):
    c = atoms.cell.array
    if len(size) == 2:
        return float(c[1, 1]) * 1.0          # plane strain: unit thickness
    return float(c[1, 1] * c[2, 2])

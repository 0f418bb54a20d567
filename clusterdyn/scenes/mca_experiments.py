"""Uniaxial tension / compression of an MCA bar with grips (shared by scenes, tests and studies).

The bar lies along x; one layer of automata at each end is a grip driven
along x with a smoothly ramped velocity (``+-v/2``, lateral motion free, no
rotation); pairs within 1.2 d of a grip do not break (glued grips, so the
crack forms in the gauge section).  Engineering stress = mean of the two grip reactions / cross-section
(tension positive); strain = change of the grip distance / initial distance.
"""

import math

import numpy as np

from ..errors import InputError
from ..build.mca import mca_packing
from ..mca.calculator import MCA
from ..mca.dynamics import Grip, MCADynamics, wave_speeds


def broken_links(state, npairs0):
    """Per automaton (state rows), the number of its set-up links now unlinked."""
    lk = state.linked_p[:npairs0] == 0
    ids = state.pid_p2[:npairs0][lk].ravel()
    rows = state.rows(state.id_n)
    return np.bincount(rows[ids], minlength=len(state.id_n))


def uniaxial(material, mode="tension", d=1.0, size=(16, 5, 5), packing="fcc", strain_max=None,
             steps=3000, ramp=0.1, damping=0.05, scatter=0.0, seed=0, dim=3, path=None,
             interval=20, progress=False, observers=(), stop_after_peak=None, pbc_lateral=False,
             h5md=None, frames=20, prepare=None):
    """Drive a bar in tension or compression; return a dict with the curve and the run objects.

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
        (for unload/reload cycles); default linear after the ramp
    stop_after_peak : stop when the stress has fallen below this fraction of the peak
    prepare : optional callable ``f(atoms)`` run on the sample before the MCA state is
        built (pre-cracks, material ids)
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
    probe = MCADynamics(atoms, damping=damping)
    dt = probe.dt
    T = steps * dt
    t_r = ramp * T
    # displacement path: u(t) = strain(t) * L0, velocity = du/dt of each grip (+-1/2)
    if path is None:
        # linear with a smooth start: velocity ramps over t_r, then constant; total = strain_max
        v_end = strain_max * L0 / (T - 0.5 * t_r)

        def vel(t):
            if t < t_r:
                return v_end * 0.5 * (1 - math.cos(math.pi * t / t_r))
            return v_end
    else:
        h = 1e-4

        def vel(t):
            s = t / T
            return (path(min(s + h, 1.0)) - path(max(s - h, 0.0))) / (2 * h * T) * strain_max * L0 \
                if 0 <= s <= 1 else 0.0
    g_lo = Grip(lo, 0, lambda t: -0.5 * sign * vel(t))
    g_hi = Grip(hi, 0, lambda t: 0.5 * sign * vel(t))
    dyn = MCADynamics(atoms, damping=damping, grips=[g_lo, g_hi])
    for obs, n in observers:
        dyn.attach(obs, interval=n)
    h5md_path = h5md_error = None
    writer = None
    if h5md is not None:
        try:
            from ..io import H5MDWriter
        except ImportError as exc:          # optional: the writer may not be installed
            H5MDWriter = None
            h5md_error = f"no H5MD output: {exc}"
        if H5MDWriter is not None:
            npairs0 = st.npairs
            writer = H5MDWriter(str(h5md), atoms, dyn=dyn, per_particle={
                "mca_stress": lambda a: a.calc.get_property("stresses", a),
                "broken_links": lambda a: broken_links(dyn.state, npairs0)[dyn.state.pair_rows(a)[5]],
                "links": lambda a: _links(dyn.state, a),
            })
            dyn.attach(writer, interval=max(1, steps // frames))
            h5md_path = h5md
    area = _area(atoms, d, size)
    strain, stress, ts = [0.0], [0.0], [0.0]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=steps, desc=f"mca-{mode}", unit="step")
    peak = 0.0
    done = 0
    while done < steps:
        k = min(interval, steps - done)
        dyn.run(k)
        done += k
        if bar is not None:
            bar.update(k)
        e = (g_hi.displacement - g_lo.displacement) / L0
        s = 0.5 * (g_hi.reaction - g_lo.reaction) / area
        strain.append(sign * e)
        stress.append(sign * s)
        ts.append(dyn.state.time)
        peak = max(peak, sign * s)
        if stop_after_peak is not None and peak > 0.5 * ref and sign * s < stop_after_peak * peak:
            break
    if bar is not None:
        bar.close()
    if writer is not None:
        writer.close()
    strain = np.array(strain)
    stress = np.array(stress)
    k = int(np.argmax(stress))
    return {"strain": strain, "stress": stress, "time": np.array(ts), "peak_stress": stress[k],
            "strain_at_peak": strain[k], "atoms": atoms, "dyn": dyn, "npairs0": npairs0,
            "reference": ref, "area": area, "L0": L0, "wave_speeds": wave_speeds(material),
            "h5md_path": h5md_path, "h5md_error": h5md_error}


def _links(state, atoms):
    """Linked pairs per automaton (rows of ``atoms``)."""
    i_p, j_p = state.pair_rows(atoms)[:2]
    lk = state.linked_p == 1
    return np.bincount(np.concatenate([i_p[lk], j_p[lk]]), minlength=len(atoms))


def _area(atoms, d, size):
    c = atoms.cell.array
    if len(size) == 2:
        return c[1, 1] * 1.0          # plane strain: unit thickness
    return c[1, 1] * c[2, 2]

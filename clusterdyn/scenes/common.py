"""Pieces shared by scenes: initial noise, a frame loop with progress, plotting set-up."""

import time

import numpy as np

from ..md.layer_drives import Piston


def thermal_noise(atoms, rms, seed, exclude=None):
    """Add seeded Gaussian velocities of ``rms`` speed (3-D rms) with zero total momentum."""
    if not rms:
        return
    rng = np.random.default_rng(seed)
    v = rng.normal(0.0, rms / np.sqrt(3.0), (len(atoms), 3))
    m = atoms.get_masses()
    keep = np.ones(len(atoms), bool) if exclude is None else ~np.asarray(exclude, bool)
    v[~keep] = 0.0
    v[keep] -= (m[keep, None] * v[keep]).sum(axis=0) / m[keep].sum()
    atoms.set_velocities(atoms.get_velocities() + v)


#: set once a run in this process has taken a step (numba kernels compiled or loaded from the cache)
_STEPPED = []


def run_frames(dyn, nsteps, nframes, on_frame, progress=True, desc="run", checkpoint=None,
               checkpoint_every=0, save=None, stop=None):
    """Run up to step ``nsteps``, calling ``on_frame(dyn)`` every ``nsteps/nframes`` steps.

    The frame at step 0 is taken unless the dynamics is resumed (``dyn.nsteps > 0``:
    a restart continues after its last frame).  Every ``checkpoint_every``
    frames (0 = never) ``save(checkpoint)`` writes the full state.  Shows one
    tqdm bar over all steps with time left when ``progress``; the first step of
    a process says "compiling kernels, first run only" while numba compiles
    (or loads its on-disk cache).  ``stop(dyn)``, if given, is asked after
    every frame; True ends the run there.  Returns the wall time of the
    stepping alone.
    """
    every = max(1, int(round(nsteps / max(1, nframes))))
    bar = None
    done = dyn.nsteps
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=nsteps, initial=done, desc=desc, unit="step", leave=False, dynamic_ncols=True)
    if done == 0:
        on_frame(dyn)
    t_run = 0.0
    nframe = done // every
    try:
        while done < nsteps:
            k = min(every - done % every, nsteps - done)
            t0 = time.perf_counter()
            if not _STEPPED and k > 1:
                if bar is not None:
                    bar.set_description_str(f"{desc} (compiling kernels, first run only)")
                dyn.run(1)
                _STEPPED[:1] = [True]
                if bar is not None:
                    bar.set_description_str(desc)
                    bar.update(1)
                dyn.run(k - 1)
                if bar is not None:
                    bar.update(k - 1)
            else:
                dyn.run(k)
                _STEPPED[:1] = [True]
                if bar is not None:
                    bar.update(k)
            t_run += time.perf_counter() - t0
            done += k
            on_frame(dyn)
            nframe += 1
            if stop is not None and stop(dyn):
                break
            if checkpoint and checkpoint_every and nframe % checkpoint_every == 0 and done < nsteps:
                save(checkpoint)
    finally:
        if bar is not None:
            bar.close()
    return t_run


def piston_thickness(r0):
    """Thickness of a scene's piston layer: 1.5 r0 (at least two atomic planes in every orientation),
    less 1e-6 r0 so that no plane sits on the boundary (Angstrom, as ``r0``)."""
    return 1.5 * r0 - 1e-6 * r0


def piston_layer(atoms, thickness, axis=0):
    """Mask of the particles within ``thickness`` of the lowest coordinate along ``axis``."""
    x = atoms.positions[:, axis]
    return x < x.min() + thickness


def make_piston(atoms, thickness, u, axis=0):
    mask = piston_layer(atoms, thickness, axis)
    v = np.zeros(3)
    v[axis] = u
    return mask, Piston(mask, v)


def matplotlib_agg():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def ledger_joules(ledger):
    """An energy ledger (:meth:`clusterdyn.md.DampedVerlet.energy_ledger`, eV) as JSON-encodable values
    in the unit every scene reports energies in, joules; the removed momentum in N s
    (``removed_momentum_N_s``)."""
    from .. import units
    out = {}
    for k, x in ledger.items():
        if k == "removed_momentum":
            out["removed_momentum_N_s"] = (np.asarray(x, float) / (units.N * units.s)).tolist()
        else:
            out[k] = float(x) / units.J
    return out

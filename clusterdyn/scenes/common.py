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


class _CompileLabel:
    """Says "compiling kernels" on the bar while numba actually compiles (its ``numba:compile``
    event, which a kernel loaded from the on-disk cache does not raise), and restores the label."""

    def __init__(self, bar, desc):
        self.bar, self.desc, self.depth, self.compiled = bar, desc, 0, False
        self.listener = None
        if bar is None:
            return
        from numba.core import event

        label = self

        class Listener(event.Listener):
            def on_start(self, ev):
                label.depth += 1
                label.compiled = True
                if label.depth == 1:
                    label.bar.set_description_str(f"{label.desc} (compiling kernels: first run after install "
                                                  "or a code change, then cached on disk)")

            def on_end(self, ev):
                label.depth -= 1
                if label.depth == 0:
                    label.bar.set_description_str(label.desc)

        self.listener = Listener()

    def __enter__(self):
        if self.listener is not None:
            from numba.core import event
            event.register("numba:compile", self.listener)
        return self

    def __exit__(self, *exc):
        if self.listener is not None:
            from numba.core import event
            event.unregister("numba:compile", self.listener)
        return False


def _restart_rate(bar, n):
    """Forget the time spent so far in the bar's rate (set-up, compiling or loading kernels):
    the time left shows "?" until the next steps, then counts from their pace."""
    bar.reset(total=bar.total)
    bar.initial = bar.n = bar.last_print_n = n
    bar.refresh()


def _expected(expected, stop):
    if expected is None and stop is not None:
        expected = getattr(getattr(stop, "__self__", None), "expected_steps", None)
    return expected


def run_frames(dyn, nsteps, nframes, on_frame, progress=True, desc="run", checkpoint=None,
               checkpoint_every=0, save=None, stop=None, expected=None):
    """Run up to step ``nsteps``, calling ``on_frame(dyn)`` every ``nsteps/nframes`` steps.

    The frame at step 0 is taken unless the dynamics is resumed (``dyn.nsteps > 0``:
    a restart continues after its last frame).  Every ``checkpoint_every``
    frames (0 = never) ``save(checkpoint)`` writes the full state.  Shows one
    tqdm bar over all steps with time left when ``progress``.  The first
    step is taken alone; the bar shows no time left until the steps after
    it move (its rate then leaves out the set-up and the kernels' start), and
    says "compiling kernels" only while numba really compiles (the first run
    after install or after a change of the code; later runs load the kernels
    from numba's on-disk cache).  ``stop(dyn)``, if given, is asked after
    every frame; True ends the run there.  ``expected(dyn)``, if given (or
    the ``expected_steps(dyn)`` method of the object whose method ``stop``
    is), returns the step at which the run is expected to stop (or None):
    the bar counts to it instead of ``nsteps``, so that its time left is to
    the expected stop.  Returns the wall time of the stepping alone.
    """
    every = max(1, int(round(nsteps / max(1, nframes))))
    bar = None
    done = dyn.nsteps
    expected = _expected(expected, stop)
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=nsteps, initial=done, desc=desc, unit="step", leave=False, dynamic_ncols=True)
    if done == 0:
        on_frame(dyn)
    t_run = 0.0
    nframe = done // every
    first = True
    try:
        with _CompileLabel(bar, desc):
            while done < nsteps:
                k = min(every - done % every, nsteps - done)
                t0 = time.perf_counter()
                if first and k > 1:
                    dyn.run(1)
                    if bar is not None:
                        _restart_rate(bar, done + 1)
                    dyn.run(k - 1)
                    if bar is not None:
                        bar.update(k - 1)
                else:
                    dyn.run(k)
                    if bar is not None:
                        bar.update(k)
                first = False
                t_run += time.perf_counter() - t0
                done += k
                on_frame(dyn)
                nframe += 1
                if bar is not None and expected is not None:
                    want = expected(dyn)
                    if want is not None:
                        bar.total = int(min(nsteps, max(done, want)))
                        bar.refresh()
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

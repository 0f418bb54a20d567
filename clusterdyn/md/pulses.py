"""Histories of a drive shaped as a pulse: a piston's U(t), or a boundary's stress.

A piston pushed at a constant speed u drives a steady shock of particle
velocity u.  A pulse of finite duration is a *flat top then a release*: the
piston rises from rest to u in ``rise`` (0: a jump), holds u for ``flat``,
then slows linearly to ``u_end`` over ``release`` and holds ``u_end``
(default 0: the piston stops, as the rear face of a flyer plate does after
its release wave has crossed it).  The shock then carries a plateau of
length about ``D * flat`` followed by a release fan about ``D * release``
long.  The history is a piecewise-linear :class:`~clusterdyn.md.histories.Table`
(exact displacement in the piston's steps, storable in checkpoints).

``flat=None`` holds u for ever (a constant piston, with an optional rise).

The same shape drives a :class:`~clusterdyn.md.layer_drives.Traction` layer with a
normal stress history (a pressure boundary): there the boundary is free to
move, so after the release it is a stress-free face, as the rear of a
flyer or a target's far side, and tension that comes back to it is not
held (a rigid piston holding U(t) reflects it as tension).

Which u gives which pressure is a property of the material model (its CD
Hugoniot), not of the piston: the scenes size u from the model's own
measured Hugoniot (:mod:`clusterdyn.scenes.pressure`).
"""

import math

import numpy as np

from ..errors import InputError
from .histories import Table

__all__ = ["flat_top", "pulse_end"]


def _nonneg(name, v):
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(name, v, "a time >= 0 (ASE units)") from None
    if not (math.isfinite(x) and x >= 0):
        raise InputError(name, v, "a finite time >= 0 (ASE units)")
    return x


def flat_top(u, flat, release=0.0, *, rise=0.0, u_end=0.0):
    """U(t) of a flat-topped pulse: rise to ``u``, hold for ``flat``, release to ``u_end``.

    The same shape serves any history of a drive: a piston's speed, or the
    normal stress of a :class:`~clusterdyn.md.layer_drives.Traction` (then ``u`` and
    ``u_end`` are stresses, eV/Angstrom^3).

    Parameters
    ----------
    u : float
        Plateau value (a speed, Angstrom / ASE time, or a stress), > 0.
    flat : float or None
        Plateau duration, ASE time (>= 0); None holds ``u`` to the end of any run.
    release : float
        Duration of the linear release from ``u`` to ``u_end``, ASE time
        (0: a drop at the end of the plateau, taken over one step of the
        dynamics since the table is piecewise linear: give a positive release
        for a resolved fan).
    rise : float
        Duration of the linear rise from 0 to ``u``, ASE time (0: a jump, the
        steady-shock piston).
    u_end : float
        Value held after the release, in [0, u].

    Returns
    -------
    Table
        Piecewise-linear values through the knots (speeds along the piston's
        direction, or stresses); held at the last value after them.
    """
    try:
        u = float(u)
    except (TypeError, ValueError):
        raise InputError("u", u, "a positive plateau value") from None
    if not (math.isfinite(u) and u > 0):
        raise InputError("u", u, "a positive finite plateau value")
    rise = _nonneg("rise", rise)
    release = _nonneg("release", release)
    try:
        u_end = float(u_end)
    except (TypeError, ValueError):
        raise InputError("u_end", u_end, f"a value in [0, u = {u:.6g}]") from None
    if not (0.0 <= u_end <= u):
        raise InputError("u_end", u_end, f"a value in [0, u = {u:.6g}]")
    t = [0.0]
    v = [0.0 if rise > 0 else u]
    if rise > 0:
        t.append(rise)
        v.append(u)
    if flat is None:
        if len(t) == 1:
            return Table([0.0], [u])
        return Table(t, v)
    flat = _nonneg("flat", flat)
    t_top = rise + flat
    if t_top > t[-1]:
        t.append(t_top)
        v.append(u)
    # a release of zero length becomes a step over a tiny interval (a Table needs increasing times)
    t_end = t_top + (release if release > 0 else 1e-9 * max(t_top, 1.0))
    t.append(t_end)
    v.append(u_end)
    return Table(np.array(t), np.array(v))


def pulse_end(table):
    """Time after which a piston history stays at its last value (its last knot), ASE time."""
    if not isinstance(table, Table):
        raise InputError("table", type(table).__name__, "a Table")
    return float(table.times[-1])

"""The segment method for contacting surfaces and the mesoscale friction law (2D plane strain).

docs/theory.md (MCA, contacting surfaces) gives the equations; docs/mca_contact.md the
choices we made and the checks.  Summary:

* Bodies are labelled by the per-automaton array ``atoms.arrays['body']`` (int).  Pairs
  across two bodies are not in the MCA pair table (no linking, no ordinary contact):
  while segments are on, the bodies meet only through the segment force.
* A *surface segment* (a, b) of a body is a linked pair of that body with no common
  linked neighbour on one side (the outward side); it is found again at every
  evaluation, so it follows deformation and fracture.  Segments are stored oriented so
  that the outward normal is the left normal of a -> b: ``n = (-t_y, t_x)``.
* An automaton k of another body (k a surface automaton of its own body) interacts with
  the segment whose foot point lies between a and b (``0 <= l_a <= r``) with the
  smallest height ``-h0 < h < h0``, ``h0 = sqrt(3) R`` (R the mean radius of k, a, b);
  at most one segment per other body.
* Normal force ``F_N = E* r0 (h0 - h)/h0`` on k along n, ``-F_N l_b/r`` on a and
  ``-F_N l_a/r`` on b (lever rule), potential ``U = E* r0 (h0 - h)^2 / (2 h0)``;
  ``1/E* = (1 - nu_k^2)/E_k + (1 - nu_s^2)/E_s`` (s: the segment's mean), unit thickness.
* Friction at the foot point: ``F_R = -[mu0 r0 V + s(V) min((mu1 + K_mu) F_N, tau0 r0)]``
  along the segment direction t, ``s(V) = V/sqrt(V^2 + v_reg^2)``, ``V`` the relative
  tangential velocity at the foot (k's centre velocity plus its spin, minus the
  segment's material velocity ``(l_b v_a + l_a v_b)/r``); on k with the torque
  ``(-h n) x F_R``, its opposite shared to a and b with the weights l_b/r, l_a/r.
* Interlocking ``K_mu = max(0, K_av + sum_m A_m^n/R sin(pi (x_m - l_m^n)/l_m^n))`` along the
  contact's sliding path x (signed, from 0 when the contact forms); each sinusoid runs in
  sections of whole half-periods drawn from a counter-based generator keyed by
  (seed, automaton id, body, sinusoid, draw number): the history is a handful of numbers
  per contact, saved in checkpoints, and a restart continues bit for bit.

Kernels are module-level ``@njit(cache=True)``; a run without friction never calls the
friction kernels, a run without interlocking calls :func:`friction_coulomb` (no history).
"""

import math

import numpy as np
from numba import njit

from .. import units
from ..errors import InputError
from ..neighbors.image import image_component

#: fields of the per-(automaton, body) contact history (state rows x bodies)
HISTORY = ("active", "x", "xs", "xe", "amp", "half", "ndraw")


# ----------------------------------------------------------------------------- kernels
@njit(cache=True)
def _sep(pos, a, b, box_c, periodic_c):
    dx = pos[b, 0] - pos[a, 0]
    dy = pos[b, 1] - pos[a, 1]
    if periodic_c[0]:
        dx = image_component(dx, box_c[0])
    if periodic_c[1]:
        dy = image_component(dy, box_c[1])
    return dx, dy


@njit(cache=True)
def surface_segments(pos, i_p, j_p, linked_p, first_n, side_p, side_s, body_n, box_c, periodic_c, seg_s3):
    """Surface segments: linked same-body pairs with no common linked neighbour on one side.

    Writes ``seg_s3[s] = (a, b, p)`` oriented so that the empty (outward) side is on the left
    of a -> b; returns the number of segments (a pair with both sides empty gives two).
    """
    ns = 0
    for p in range(i_p.shape[0]):
        if linked_p[p] == 0:
            continue
        i = i_p[p]
        j = j_p[p]
        if body_n[i] != body_n[j]:
            continue
        dx, dy = _sep(pos, i, j, box_c, periodic_c)
        left = 0
        right = 0
        for k1 in range(first_n[i], first_n[i + 1]):
            q = side_p[k1]
            if linked_p[q] == 0 or q == p:
                continue
            c = j_p[q] if side_s[k1] == 0 else i_p[q]
            # is c linked to j?
            common = False
            for k2 in range(first_n[j], first_n[j + 1]):
                q2 = side_p[k2]
                if linked_p[q2] == 0:
                    continue
                c2 = j_p[q2] if side_s[k2] == 0 else i_p[q2]
                if c2 == c:
                    common = True
                    break
            if not common:
                continue
            ex, ey = _sep(pos, i, c, box_c, periodic_c)
            if dx * ey - dy * ex > 0.0:
                left += 1
            else:
                right += 1
        if left == 0:
            seg_s3[ns, 0] = i
            seg_s3[ns, 1] = j
            seg_s3[ns, 2] = p
            ns += 1
        if right == 0:
            seg_s3[ns, 0] = j
            seg_s3[ns, 1] = i
            seg_s3[ns, 2] = p
            ns += 1
    return ns


@njit(cache=True)
def segment_contacts(pos, seg_s3, nseg, r0_p, body_n, R_n, Ep_n, box_c, periodic_c, nbody,
                     c_k, c_a, c_b, c_p, c_body, c_l, c_r, c_h, c_n2, c_h0, c_E, c_fn, f_nc):
    """Contacts of surface automata with the other bodies' segments, and their normal forces.

    For every automaton k that ends a surface segment and every other body, the segment of
    that body with the foot of k between its ends and the smallest height in (-h0, h0).
    Adds the lever-rule normal forces to ``f_nc``; fills the contact arrays; returns
    (number of contacts, potential energy of the contacts).
    """
    n = pos.shape[0]
    is_surf = np.zeros(n, np.int8)
    for s in range(nseg):
        is_surf[seg_s3[s, 0]] = 1
        is_surf[seg_s3[s, 1]] = 1
    best_s = np.empty(nbody, np.int64)
    best_h = np.empty(nbody)
    best_l = np.empty(nbody)
    best_r = np.empty(nbody)
    best_h0 = np.empty(nbody)
    nc = 0
    energy = 0.0
    for k in range(n):
        if is_surf[k] == 0:
            continue
        bk = body_n[k]
        for b in range(nbody):
            best_s[b] = -1
            best_h[b] = np.inf
        for s in range(nseg):
            a = seg_s3[s, 0]
            b = seg_s3[s, 1]
            bs = body_n[a]
            if bs == bk:
                continue
            tx, ty = _sep(pos, a, b, box_c, periodic_c)
            r = math.sqrt(tx * tx + ty * ty)
            tx /= r
            ty /= r
            wx, wy = _sep(pos, a, k, box_c, periodic_c)
            la = wx * tx + wy * ty
            if la < 0.0 or la > r:
                continue
            h = -wx * ty + wy * tx          # along n = (-ty, tx)
            h0 = math.sqrt(3.0) * (R_n[k] + R_n[a] + R_n[b]) / 3.0
            if h >= h0 or h <= -h0:
                continue
            if h < best_h[bs]:
                best_h[bs] = h
                best_s[bs] = s
                best_l[bs] = la
                best_r[bs] = r
                best_h0[bs] = h0
        for bb in range(nbody):
            s = best_s[bb]
            if s < 0:
                continue
            a = seg_s3[s, 0]
            b = seg_s3[s, 1]
            p = seg_s3[s, 2]
            tx, ty = _sep(pos, a, b, box_c, periodic_c)
            r = best_r[bb]
            tx /= r
            ty /= r
            nx = -ty
            ny = tx
            h = best_h[bb]
            h0 = best_h0[bb]
            la = best_l[bb]
            lb = r - la
            es = 0.5 * (1.0 / Ep_n[a] + 1.0 / Ep_n[b])
            E = 1.0 / (1.0 / Ep_n[k] + es)
            fn = E * r0_p[p] * (h0 - h) / h0
            energy += 0.5 * E * r0_p[p] * (h0 - h) * (h0 - h) / h0
            f_nc[k, 0] += fn * nx
            f_nc[k, 1] += fn * ny
            f_nc[a, 0] -= fn * nx * lb / r
            f_nc[a, 1] -= fn * ny * lb / r
            f_nc[b, 0] -= fn * nx * la / r
            f_nc[b, 1] -= fn * ny * la / r
            c_k[nc] = k
            c_a[nc] = a
            c_b[nc] = b
            c_p[nc] = p
            c_body[nc] = bb
            c_l[nc] = la
            c_r[nc] = r
            c_h[nc] = h
            c_n2[nc, 0] = nx
            c_n2[nc, 1] = ny
            c_h0[nc] = h0
            c_E[nc] = E
            c_fn[nc] = fn
            nc += 1
    return nc, energy


@njit(cache=True)
def _tangential_velocity(vel, om, k, a, b, la, r, h, nx, ny):
    tx = ny
    ty = -nx
    # t = (ny, -nx) is the segment direction a -> b;  omega x (-h n) = h omega_z t
    vk = vel[k, 0] * tx + vel[k, 1] * ty + h * om[k, 2]
    lb = r - la
    vs = ((lb * vel[a, 0] + la * vel[b, 0]) * tx + (lb * vel[a, 1] + la * vel[b, 1]) * ty) / r
    return vk - vs


@njit(cache=True)
def _apply_friction(fr, k, a, b, la, r, h, nx, ny, f_nc, t_nc):
    tx = ny
    ty = -nx
    lb = r - la
    f_nc[k, 0] += fr * tx
    f_nc[k, 1] += fr * ty
    t_nc[k, 2] += h * fr            # (-h n) x (fr t), n x t = -1
    f_nc[a, 0] -= fr * tx * lb / r
    f_nc[a, 1] -= fr * ty * lb / r
    f_nc[b, 0] -= fr * tx * la / r
    f_nc[b, 1] -= fr * ty * la / r


@njit(cache=True)
def friction_coulomb(vel, om, nc, c_k, c_a, c_b, c_p, c_l, c_r, c_h, c_n2, c_fn, r0_p,
                     mu0, mu1, tau0, v_reg, f_nc, t_nc, c_fr, c_v):
    """Viscous plus dry friction without interlocking (K_mu = 0); returns the dry force sum."""
    dry = 0.0
    for c in range(nc):
        k = c_k[c]
        a = c_a[c]
        b = c_b[c]
        r0 = r0_p[c_p[c]]
        V = _tangential_velocity(vel, om, k, a, b, c_l[c], c_r[c], c_h[c], c_n2[c, 0], c_n2[c, 1])
        s = V / math.sqrt(V * V + v_reg * v_reg)
        d = min(mu1 * c_fn[c], tau0 * r0)
        fr = -(mu0 * r0 * V + s * d)
        dry += d
        c_fr[c] = fr
        c_v[c] = V
        _apply_friction(fr, k, a, b, c_l[c], c_r[c], c_h[c], c_n2[c, 0], c_n2[c, 1], f_nc, t_nc)
    return dry


@njit(cache=True)
def _u01(seed, key, m, ndraw, which):
    """Counter-based uniform in [0, 1) (splitmix64 of the draw's coordinates)."""
    z = (np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15)
         + np.uint64(key) * np.uint64(0xBF58476D1CE4E5B9)
         + np.uint64(ndraw * 8 + m * 4 + which) * np.uint64(0x94D049BB133111EB))
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _draw(seed, key, m, ndraw, A_av, l_av, d_av):
    """A section of sinusoid m: (amplitude, half-period, length of whole half-periods)."""
    dl = (0.5 + _u01(seed, key, m, ndraw, 0)) * d_av
    amp = (0.5 + _u01(seed, key, m, ndraw, 1)) * A_av
    half = (0.5 + _u01(seed, key, m, ndraw, 2)) * l_av
    nh = max(1.0, math.floor(dl / half + 0.5))
    return amp, half, nh * half


@njit(cache=True)
def friction_interlock(vel, om, nc, c_k, c_a, c_b, c_p, c_body, c_l, c_r, c_h, c_n2, c_fn, c_R, r0_p,
                       mu0, mu1, tau0, v_reg, K_av, A_m, l_m, d_m, seed, ids_n, srow_n, nbody, dt,
                       advance, h_active, h_x, h_xs, h_xe, h_amp, h_half, h_ndraw, clips,
                       f_nc, t_nc, c_fr, c_v, c_K):
    """Friction with the interlocking history (module docstring); returns the dry force sum.

    With ``advance`` the sliding paths move by ``V dt``, sections are drawn past their ends,
    contacts not present are closed and the clips counted (once per step); without it the
    forces of the current history are returned and nothing changes.
    """
    seen = np.zeros(h_active.shape, np.int8)
    dry = 0.0
    for c in range(nc):
        k = c_k[c]
        a = c_a[c]
        b = c_b[c]
        bb = c_body[c]
        sr = srow_n[k]
        r0 = r0_p[c_p[c]]
        key = ids_n[k] * nbody + bb
        V = _tangential_velocity(vel, om, k, a, b, c_l[c], c_r[c], c_h[c], c_n2[c, 0], c_n2[c, 1])
        Kv = K_av
        if advance:
            seen[sr, bb] = 1
            if h_active[sr, bb] == 0:
                h_active[sr, bb] = 1
                h_x[sr, bb] = 0.0
                for m in range(2):
                    if A_m[m] > 0.0:
                        amp, half, ln = _draw(seed, key, m, h_ndraw[sr, bb, m], A_m[m], l_m[m], d_m[m])
                        h_ndraw[sr, bb, m] += 1
                        h_xs[sr, bb, m] = 0.0
                        h_xe[sr, bb, m] = ln
                        h_amp[sr, bb, m] = amp
                        h_half[sr, bb, m] = half
            x = h_x[sr, bb] + V * dt
            h_x[sr, bb] = x
            for m in range(2):
                if A_m[m] > 0.0:
                    while x > h_xe[sr, bb, m]:
                        amp, half, ln = _draw(seed, key, m, h_ndraw[sr, bb, m], A_m[m], l_m[m], d_m[m])
                        h_ndraw[sr, bb, m] += 1
                        h_xs[sr, bb, m] = h_xe[sr, bb, m]
                        h_xe[sr, bb, m] = h_xs[sr, bb, m] + ln
                        h_amp[sr, bb, m] = amp
                        h_half[sr, bb, m] = half
                    while x < h_xs[sr, bb, m]:
                        amp, half, ln = _draw(seed, key, m, h_ndraw[sr, bb, m], A_m[m], l_m[m], d_m[m])
                        h_ndraw[sr, bb, m] += 1
                        h_xe[sr, bb, m] = h_xs[sr, bb, m]
                        h_xs[sr, bb, m] = h_xe[sr, bb, m] - ln
                        h_amp[sr, bb, m] = amp
                        h_half[sr, bb, m] = half
        if h_active[sr, bb] == 1:
            x = h_x[sr, bb]
            for m in range(2):
                if A_m[m] > 0.0:
                    half = h_half[sr, bb, m]
                    Kv += h_amp[sr, bb, m] / c_R[c] * math.sin(math.pi * (x - h_xs[sr, bb, m] - half) / half)
        if Kv < 0.0:
            Kv = 0.0
            if advance:
                clips[0] += 1
        s = V / math.sqrt(V * V + v_reg * v_reg)
        d = min((mu1 + Kv) * c_fn[c], tau0 * r0)
        fr = -(mu0 * r0 * V + s * d)
        dry += d
        c_fr[c] = fr
        c_v[c] = V
        c_K[c] = Kv
        _apply_friction(fr, k, a, b, c_l[c], c_r[c], c_h[c], c_n2[c, 0], c_n2[c, 1], f_nc, t_nc)
    if advance:
        for i in range(h_active.shape[0]):
            for bb in range(h_active.shape[1]):
                if h_active[i, bb] == 1 and seen[i, bb] == 0:
                    h_active[i, bb] = 0
                    clips[1] += 1          # contacts closed
    return dry


# ----------------------------------------------------------------------------- the term
def _nonneg(name, v, unit=""):
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(name, v, f"a number >= 0{unit}") from None
    if not (x >= 0.0 and math.isfinite(x)):
        raise InputError(name, v, f"a number >= 0{unit}")
    return x


class SegmentContact:
    """The segment contact and friction term of :class:`~clusterdyn.mca.MCADynamics` (2D).

    Parameters
    ----------
    mu0 : float, viscous coefficient (eV/Angstrom^3 per Angstrom/ASE-time), >= 0
    mu1 : float, dry friction coefficient, >= 0
    K_av : float, mean interlocking, >= 0
    A1, A2 : float, mean amplitudes of the two sinusoids (Angstrom), >= 0 (0: sinusoid off)
    l1, l2 : float, mean half-periods (Angstrom), > 0 when the amplitude is
    d1, d2 : float, regularity lengths (mean section lengths, Angstrom), > 0 when the amplitude is
    v_reg : float, regularising velocity (default 1 mm/s), > 0
    tau0 : float, optional
        Cap of the dry part per unit segment length (eV/Angstrom^3); default
        ``sigma0/sqrt(3)``, sigma0 the elastic limit of the softer material (its yield
        stress, or its compressive strength if brittle).
    seed : int, seed of the section draws
    friction : bool, default True; False keeps only the normal (segment) force

    Notes
    -----
    All quantities in ASE units.  State (checkpointed, :meth:`get_state`): the per-(automaton, body) history
    ``active, x, xs, xe, amp, half, ndraw`` (state rows of the MCA state), the clip count
    and the friction work.
    """

    def __init__(self, mu0=0.0, mu1=0.3, K_av=0.0, A1=0.0, l1=0.0, d1=0.0, A2=0.0, l2=0.0, d2=0.0,
                 v_reg=1.0 * units.mm / units.s, tau0=None, seed=0, friction=True):
        self.mu0 = _nonneg("mu0", mu0)
        self.mu1 = _nonneg("mu1", mu1)
        self.K_av = _nonneg("K_av", K_av)
        self.A_m = np.array([_nonneg("A1", A1, " Angstrom"), _nonneg("A2", A2, " Angstrom")])
        self.l_m = np.array([_nonneg("l1", l1, " Angstrom"), _nonneg("l2", l2, " Angstrom")])
        self.d_m = np.array([_nonneg("d1", d1, " Angstrom"), _nonneg("d2", d2, " Angstrom")])
        for m in range(2):
            if self.A_m[m] > 0 and not (self.l_m[m] > 0 and self.d_m[m] > 0):
                raise InputError(f"l{m + 1}, d{m + 1}", (self.l_m[m], self.d_m[m]),
                                 f"positive half-period and regularity length when A{m + 1} > 0")
        self.v_reg = _nonneg("v_reg", v_reg, " (Angstrom/ASE-time)")
        if not self.v_reg > 0:
            raise InputError("v_reg", v_reg, "a positive regularising velocity")
        self.tau0 = None if tau0 is None else _nonneg("tau0", tau0, " eV/Angstrom^3")
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputError("seed", seed, "an integer >= 0")
        self.seed = int(seed)
        self.friction_on = bool(friction) and (self.mu0 > 0 or self.mu1 > 0 or self.K_av > 0
                                               or bool(np.any(self.A_m > 0)))
        self.interlock = self.friction_on and (self.K_av > 0 or bool(np.any(self.A_m > 0)))
        self.friction_work = 0.0
        self.clips = np.zeros(2, np.int64)      # [K_mu clips (contact-steps), contacts closed]
        self.hist = None
        self.geo = None
        self.last = None

    # ---------------------------------------------------------------- set-up
    def params(self):
        """The constructor's arguments (what a checkpoint stores to rebuild the term)."""
        return {"mu0": self.mu0, "mu1": self.mu1, "K_av": self.K_av, "A1": float(self.A_m[0]),
                "l1": float(self.l_m[0]), "d1": float(self.d_m[0]), "A2": float(self.A_m[1]),
                "l2": float(self.l_m[1]), "d2": float(self.d_m[1]), "v_reg": self.v_reg,
                "tau0": self.tau0, "seed": self.seed, "friction": self.friction_on}

    def bind(self, atoms, state):
        """Check the sample (2D, bodies) and drop the pairs across bodies from ``state``."""
        if state.dim != 2:
            raise InputError("dim", state.dim, "2 (plane strain): the segment method is 2D only (3D facets "
                             "are not implemented)")
        if "body" not in atoms.arrays:
            raise InputError("atoms", "no array 'body'", "a per-automaton body label (int), e.g. from "
                             "stack_blocks")
        body = np.asarray(atoms.arrays["body"])
        if body.min() < 0:
            raise InputError("body", int(body.min()), "body labels >= 0")
        self.nbody = int(body.max()) + 1
        if self.nbody < 2:
            raise InputError("body", "one body", "at least two bodies to contact")
        # pairs across bodies leave the pair table (the bodies meet through segments only)
        bid = np.full(int(np.max(atoms.arrays["id"])) + 1, -1, np.int64)
        bid[np.asarray(atoms.arrays["id"], np.int64)] = body
        cross = bid[state.pid_p2[:, 0]] != bid[state.pid_p2[:, 1]]
        if cross.any():
            state.remove_pairs(~cross)
        mats = state.materials
        E = np.array([9.0 * m.K * m.G / (3.0 * m.K + m.G) for m in mats])
        nu = np.array([(3.0 * m.K - 2.0 * m.G) / (2.0 * (3.0 * m.K + m.G)) for m in mats])
        self.Ep_m = E / (1.0 - nu * nu)
        if self.tau0 is None:
            s0 = [m.sigma_y if m.sigma_y else (m.sigma_c if m.sigma_c else np.inf) for m in mats]
            self.tau0_used = float(min(s0)) / math.sqrt(3.0)
        else:
            self.tau0_used = self.tau0
        if self.hist is None:
            n = len(atoms)
            self.hist = {"active": np.zeros((n, self.nbody), np.int8), "x": np.zeros((n, self.nbody)),
                         "xs": np.zeros((n, self.nbody, 2)), "xe": np.zeros((n, self.nbody, 2)),
                         "amp": np.zeros((n, self.nbody, 2)), "half": np.ones((n, self.nbody, 2)),
                         "ndraw": np.zeros((n, self.nbody, 2), np.int64)}
        return self

    # ---------------------------------------------------------------- evaluation
    def normal(self, atoms, state):
        """Normal (segment) forces (N, 3) at the current positions; keeps the contact geometry."""
        i_p, j_p, first_n, side_p, side_s, perm = state.pair_rows(atoms)
        pos = np.ascontiguousarray(atoms.positions, dtype=np.float64)
        n = len(atoms)
        body = np.ascontiguousarray(atoms.arrays["body"], dtype=np.int64)
        box_c, periodic_c = state.box_c, state.periodic_c
        seg = np.empty((2 * len(i_p) + 1, 3), np.int64)
        ns = surface_segments(pos, i_p, j_p, state.linked_p, first_n, side_p, side_s, body, box_c,
                              periodic_c, seg)
        R_n = np.ascontiguousarray(atoms.arrays["radius"], dtype=np.float64)
        Ep_n = self.Ep_m[state.mat_id_n[perm]]
        m = n * self.nbody
        g = {"k": np.empty(m, np.int64), "a": np.empty(m, np.int64), "b": np.empty(m, np.int64),
             "p": np.empty(m, np.int64), "body": np.empty(m, np.int64), "l": np.empty(m),
             "r": np.empty(m), "h": np.empty(m), "n": np.empty((m, 2)), "h0": np.empty(m), "E": np.empty(m),
             "fn": np.empty(m)}
        f = np.zeros((n, 3))
        nc, e = segment_contacts(pos, seg, ns, state.r0_p, body, R_n, Ep_n, box_c, periodic_c, self.nbody,
                                 g["k"], g["a"], g["b"], g["p"], g["body"], g["l"], g["r"], g["h"], g["n"],
                                 g["h0"], g["E"], g["fn"], f)
        g = {k: v[:nc] for k, v in g.items()}
        if self.interlock:             # the meso-volume's size A = R (the interlocking law's only user)
            g["R"] = (R_n[g["k"]] + R_n[g["a"]] + R_n[g["b"]]) / 3.0
        g["nc"] = nc
        g["nseg"] = ns
        g["segments"] = seg[:ns]         # (automaton a, automaton b, pair row) of each surface segment
        g["energy"] = e
        g["perm"] = perm
        self.geo = g
        return f

    def friction(self, atoms, state, vel, omega, dt, advance):
        """Friction forces and torques (N, 3) at velocities ``vel``/``omega`` on the last geometry.

        ``advance`` moves the histories by one step (called once per step by the dynamics).
        """
        g = self.geo
        n = len(atoms)
        f = np.zeros((n, 3))
        t = np.zeros((n, 3))
        nc = g["nc"]
        fr = np.empty(nc)
        V = np.empty(nc)
        Kc = np.full(nc, self.K_av)
        vel = np.ascontiguousarray(vel, dtype=np.float64)
        om = np.ascontiguousarray(omega, dtype=np.float64)
        r0_p = np.ascontiguousarray(state.r0_p, dtype=np.float64)
        if self.interlock:
            h = self.hist
            ids = np.ascontiguousarray(atoms.arrays["id"], dtype=np.int64)
            dry = friction_interlock(vel, om, nc, g["k"], g["a"], g["b"], g["p"], g["body"], g["l"], g["r"],
                                     g["h"], g["n"], g["fn"], g["R"], r0_p, self.mu0, self.mu1,
                                     self.tau0_used, self.v_reg, self.K_av, self.A_m, self.l_m, self.d_m,
                                     self.seed, ids, np.ascontiguousarray(g["perm"], dtype=np.int64),
                                     self.nbody, float(dt), bool(advance), h["active"], h["x"], h["xs"],
                                     h["xe"], h["amp"], h["half"], h["ndraw"], self.clips, f, t, fr, V, Kc)
        else:
            dry = friction_coulomb(vel, om, nc, g["k"], g["a"], g["b"], g["p"], g["l"], g["r"], g["h"],
                                   g["n"], g["fn"], r0_p, self.mu0, self.mu1, self.tau0_used, self.v_reg,
                                   f, t, fr, V)
        self.last = {"fr": fr, "V": V, "K": Kc, "dry": dry}
        return f, t

    # ---------------------------------------------------------------- records
    def summary(self):
        """Contact state now: contacts, segments, sum F_N, sum ``|F_R|``, mean K_mu, potential energy."""
        g = self.geo
        out = {"contacts": int(g["nc"]), "segments": int(g["nseg"]), "sum_FN": float(g["fn"].sum()),
               "energy": float(g["energy"]), "clips": int(self.clips[0]), "closed": int(self.clips[1]),
               "friction_work": float(self.friction_work)}
        if self.last is not None and len(self.last["fr"]):
            out["sum_FR"] = float(np.abs(self.last["fr"]).sum())
            out["mean_K"] = float(np.mean(self.last["K"]))
        return out

    def get_state(self):
        d = {f"hist_{k}": v.copy() for k, v in self.hist.items()}
        d["clips"] = self.clips.copy()
        d["friction_work"] = float(self.friction_work)
        return d

    def set_state(self, d):
        self.hist = {k: np.ascontiguousarray(np.array(d[f"hist_{k}"])) for k in HISTORY}
        self.hist["active"] = self.hist["active"].astype(np.int8)
        self.hist["ndraw"] = self.hist["ndraw"].astype(np.int64)
        self.clips = np.array(d["clips"], np.int64)
        self.friction_work = float(d["friction_work"])


# ----------------------------------------------------------------------------- building
def stack_blocks(blocks, gap=None):
    """Stack 2D MCA blocks along y into one sample with one MCA state, bodies labelled.

    Parameters
    ----------
    blocks : list of ase.Atoms from :func:`~clusterdyn.build.mca_packing` (2D, same periodic
        x length and materials list, each with its own ``material`` ids)
    gap : float, optional, distance (Angstrom) between the top row of a block and the bottom
        row of the next; default ``sqrt(3) R`` (the segment method's h0: touching, no force)

    Returns
    -------
    ase.Atoms with ``arrays['body']`` (block index), stable ids 0..N-1, and an MCA
    calculator whose state is the union of the blocks' own states (each block tessellated
    alone, so its surface automata keep their surface cells; no pairs across blocks).
    """
    from .calculator import MCA
    from .state import MCAState, PAIR_ARRAYS, ATOM_ARRAYS
    if len(blocks) < 2:
        raise InputError("blocks", len(blocks), "two or more blocks")
    for b in blocks:
        if b.info.get("mca_dim", 3) != 2:
            raise InputError("blocks", "a 3D block", "2D (plane strain) blocks: the segment method is 2D only")
    mats = blocks[0].info["mca_materials"]
    Lx = blocks[0].cell[0, 0]
    for b in blocks[1:]:
        if bool(b.pbc[0]) != bool(blocks[0].pbc[0]) or (b.pbc[0] and abs(b.cell[0, 0] - Lx) > 1e-9 * Lx):
            raise InputError("blocks", f"periodic x lengths {[float(x.cell[0, 0]) for x in blocks]}",
                             "blocks with the same periodicity and the same periodic length along x")
    states = [MCAState(b) for b in blocks]
    parts, dicts = [], []
    y = 0.0
    off = 0
    for k, (b, st) in enumerate(zip(blocks, states)):
        a = b.copy()
        a.info = dict(b.info)
        R = float(np.mean(a.arrays["radius"]))
        g = math.sqrt(3.0) * R if gap is None else float(gap)
        ys = a.positions[:, 1]
        shift = 0.0 if k == 0 else y + g - ys.min()
        a.positions[:, 1] += shift
        y = a.positions[:, 1].max()
        a.arrays["id"] = a.arrays["id"] + off
        a.new_array("body", np.full(len(a), k, np.int64))
        d = st.get_state()
        d["pid_p2"] = d["pid_p2"] + off
        d["id_n"] = d["id_n"] + off
        dicts.append(d)
        parts.append(a)
        off += len(a)
    atoms = parts[0]
    for a in parts[1:]:
        atoms = atoms + a
    atoms.info = dict(blocks[0].info)
    atoms.info["mca_materials"] = mats
    top = atoms.positions[:, 1].max() + 0.5 * 2 * atoms.arrays["radius"].max()
    atoms.cell = np.diag([Lx, top, 1.0])      # z: the unit thickness (1 Angstrom) of plane strain
    merged = {k: np.concatenate([d[k] for d in dicts]) for k in PAIR_ARRAYS + ATOM_ARRAYS}
    merged.update({"step": 0, "time": 0.0, "version": 0})
    calc = MCA(materials=mats, dim=2)
    atoms.calc = calc
    calc.state = MCAState.from_dict(atoms, merged, mats, None, 2)
    return atoms

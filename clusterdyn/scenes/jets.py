"""Scene ``jets``: a shock breaking out of a sinusoidal free surface (the CD paper's fig. 25).

Ogorodnikov et al. (the CD paper's ref. 20) drove an aluminium-alloy plate
whose free surface was a sinusoid of amplitude 1 mm and wavelength 10 mm
with about 30 GPa; jets left the valleys at about 3.7 km/s while the
continuous material moved at about 3.2 km/s (ratio 1.16).  This scene runs
that sinusoid in quasi-2D (one wavelength across, periodic; the paper's
aluminium, its tabulated cold curve) at a coarse r0, driven by a piston
held at the speed that gives the target pressure in the CD model
(:mod:`clusterdyn.scenes.pressure`), and reports the jet-tip and
free-surface velocities against time (:mod:`clusterdyn.analysis.ejecta`)
and their ratio against 1.16.

The same scene measures the growth of a **small perturbation**
(``k eta0 <= 0.1``, e.g. lead with ``amplitude`` a few r0 and a long
``wavelength``): the signed amplitude eta(t) of the initial cosine mode of
the surface, its rate after the shock has passed the crests against
Richtmyer's impulsive estimate for a free surface,
``d eta/dt = -k eta0+ u_fs`` with ``eta0+ = eta0 (1 - u_fs/D)`` (u_fs and D
measured in the run), whether the perturbation inverts, and the regime of
the shocked lattice (ordered fraction behind the front,
:mod:`clusterdyn.analysis.order`): a disordered lattice flows like the
fluid of Richtmyer's model; an ordered one has strength, which slows or
stops the growth.

**Amplitude**: ``amplitude`` is the sinusoid's amplitude eta0 (half its
peak-to-valley height), the a0 of Richtmyer's estimate.

**Depth**: the mean surface lies ``depth`` above the piston (default one
wavelength, 10 mm): the release reflected from the surface comes back from
the piston, which keeps pushing, as a tension wave only after about
``2 depth / c`` past breakout, beyond the default 3.5 us.

**Damping**: ``J = 50`` by default (free-surface scenes run damped); the
jet ratio with ``J=none`` is the undamped run.
"""

import csv
import math

import numpy as np

from .. import units
from ..analysis.ejecta import fit_rate
from ..build.profiled import Sinusoid
from ..errors import InputError
from .base import Param, Quantity, register_scene
from .common import matplotlib_agg
from .ejecta import CD_MATERIALS, ProfiledShockScene, drive_params
from .lifecycle import scene_params

#: Richtmyer's impulse is taken as over once the free surface moves at this fraction of its final speed
IMPULSE_OVER = 0.9
#: the experiment of fig. 25: jets / free surface
JET_RATIO_EXPERIMENT = 3.7 / 3.2

JETS_PARAMS = [
    Param("material", "Al", "material (the paper's aluminium: its cold-curve table)", kind="choice",
          choices=CD_MATERIALS),
    Param("amplitude", 1.0, "sinusoid amplitude eta0 (half the peak-to-valley height)", unit="mm", low=0.0,
          low_open=True),
    Param("wavelength", 10.0, "sinusoid wavelength", unit="mm", low=0.0, low_open=True),
    Param("n_periods", 1, "wavelengths across the periodic width", kind="int", low=1),
    Param("r0", 100.0, "cluster size (coarse: the jets' geometry is mm)", unit="um", low=0.0, low_open=True),
    Param("depth", 10.0, "mean height of the surface above the piston's base", unit="mm", low=0.0,
          low_open=True),
] + drive_params(30.0, None, 0.0, 3.5) + [
    Param("jet_window", None, "start of the window over which the jet and free-surface velocities are taken "
          "(to the end); none = halfway between the shock reaching the crests and the end", unit="us", low=0.0,
          optional=True),
]


class JetsScene(ProfiledShockScene):
    """The ``jets`` scene (module docstring)."""

    name = "jets"
    description = ("shock breakout from a sinusoidal surface (fig. 25: Al, 1 mm / 10 mm, 30 GPa): jet and "
                   "free-surface velocities; small perturbations against Richtmyer")
    params = scene_params(JETS_PARAMS, h5md_frames=15)

    def geometry(self, v):
        A, lam = v.amplitude, v.wavelength
        return Sinusoid(A, lam), A, lam, v.n_periods * lam, v.r0, v.depth

    def check(self, v):
        super().check(v)
        if v.jet_window is not None and v.jet_window >= v.t_end:
            raise InputError("jet_window", f"{v.jet_window / units.us:g}us", f"none or a start before the end "
                             f"of the run, t_end = {v.t_end / units.us:g} us")
        if v.depth - v.amplitude < 10 * v.r0:
            raise InputError("depth", v.depth / units.mm, f">= amplitude + 10 r0 = "
                             f"{(v.amplitude + 10 * v.r0) / units.mm:g} mm")

    def snapshot_times(self, v):
        return [k * v.t_end / 6 for k in range(7)]

    def analyse(self, v, summaries):
        sm = summaries[0]
        info = sm["info"]
        rec, probe = self.restore(sm)
        q, pr = self.drive_quantities(v, sm, probe)
        t, xtip = rec.series("x_tip")
        _, vtip = rec.series("v_tip")
        _, ufs = rec.series("u_fs")
        _, eta = rec.series("eta")
        A, lam = info["amplitude"], info["wavelength"]
        k = 2 * np.pi / lam
        D = pr["D"] if np.isfinite(pr["D"]) else info["D_table"]
        t_valley = pr["t_hi"] if np.isfinite(pr["t_hi"]) else (info["valley0"] - info["base"]) / D
        t_crest = t_valley + 2 * A / D
        t_end = t[-1]
        notes = self.common_notes(v, sm, pr)
        notes.insert(0, f"sinusoid: amplitude eta0 = {A / units.um:g} um, wavelength {lam / units.um:g} um, "
                        f"k eta0 = {k * A:.3f}; the shock reaches the valleys at {t_valley / units.us:.3f} us and "
                        f"the crests at {t_crest / units.us:.3f} us")
        after = t >= t_crest
        # jets: tip and free-surface velocities over the second half of the time after breakout
        t_late = t_crest + 0.5 * (t_end - t_crest) if v.jet_window is None else v.jet_window
        v_jet, _, nj = fit_rate(t, xtip, t_late, t_end)
        late = t >= t_late
        u_fs = float(np.nanmean(ufs[late])) if late.any() else math.nan
        ratio = v_jet / u_fs if (np.isfinite(v_jet) and u_fs > 0) else math.nan
        q["v_jet"] = Quantity(v_jet / units.km_s, "km/s", note=f"jet-tip speed: slope of the tip position over "
                              f"{t_late / units.us:.2f}-{t_end / units.us:.2f} us ({nj} frames)")
        q["u_fs"] = Quantity(u_fs / units.km_s, "km/s", note="free-surface velocity (the body's layer below the "
                             "valley front), mean over the same window")
        q["jet_ratio"] = Quantity(ratio, "", JET_RATIO_EXPERIMENT, note="v_jet / u_fs against the experiment's "
                                  "3.7/3.2 (Ogorodnikov et al., aluminium alloy, about 30 GPa)")
        q["v_tip_end"] = Quantity(float(vtip[-1]) / units.km_s, "km/s", note="tip clusters' mean velocity at the end")
        q["v_tip_max"] = Quantity(float(np.nanmax(vtip)) / units.km_s, "km/s",
                                  note="largest tip-cluster velocity over the run")
        q["tip_ratio_max"] = Quantity(float(np.nanmax(vtip)) / u_fs if u_fs > 0 else math.nan, "",
                                      JET_RATIO_EXPERIMENT, note="largest tip velocity / u_fs")

        # Richtmyer: the impulse is over once the surface moves at (nearly) its final speed; from then on
        # the amplitude changes at a constant rate for one inversion time 1/(k u_fs)
        third = t >= t_crest + 2.0 * (t_end - t_crest) / 3.0
        u_last = float(np.nanmedian(ufs[third])) if third.any() else math.nan
        moving = after & (ufs >= IMPULSE_OVER * u_last)
        t_start = float(t[moving][0]) if moving.any() else t_crest
        tau = 1.0 / (k * u_last) if u_last > 0 else math.nan
        t_fit = min(t_start + tau, t_end) if np.isfinite(tau) else t_end
        w = (t >= t_start) & (t <= t_fit)
        u_w = float(np.nanmean(ufs[w])) if w.any() else math.nan
        slope, eta_c, ne = fit_rate(t, eta, t_start, t_fit)
        def eta0_plus(shock_speed):          # Richtmyer's amplitude after the impulse
            return A * (1.0 - u_w / shock_speed)

        eta0p = eta0_plus(D)
        rich = k * eta0p * u_w
        q["eta0_plus"] = Quantity(eta_c / units.um, "um", eta0p / units.um,
                                  note=f"eta when the surface has reached {IMPULSE_OVER:g} of its final speed "
                                       "(fit intercept) vs eta0 (1 - u_fs/D)")
        q["growth_rate"] = Quantity(-slope / units.m_s, "m/s", rich / units.m_s,
                                    note=f"-d eta/dt over {t_start / units.us:.4f}-{t_fit / units.us:.4f} us "
                                         f"({ne} frames) vs Richtmyer k eta0+ u_fs with eta0+ = eta0 (1 - u_fs/D) "
                                         f"(u_fs = {u_w / units.km_s:.3f} km/s, D = {D / units.km_s:.3f} km/s)")
        q["growth_rate_measured_eta0"] = Quantity(-slope / units.m_s, "m/s", k * eta_c * u_w / units.m_s,
                                                  note="the same against k eta0+ u_fs with the measured eta0+")
        # the zero crossing of eta (a 5-frame running mean) after the impulse: the mean rate to inversion
        eta_s = np.array([np.nanmean(eta[max(0, i - 2):i + 3]) for i in range(len(eta))])
        neg = (t >= t_start) & (eta_s < 0)
        inverted = bool(neg.any())
        t_inv = float(t[neg][0]) if inverted else math.nan
        q["inversion_rate"] = Quantity((eta_c / (t_inv - t_start)) / units.m_s if inverted and t_inv > t_start
                                       else math.nan, "m/s", k * eta_c * u_w / units.m_s,
                                       note="eta0+ / (time from the impulse to the zero crossing of eta, 5-frame "
                                            "mean) vs k eta0+ u_fs (measured eta0+): Richtmyer's eta reaches zero "
                                            "after one inversion time 1/(k u_fs)")
        # how well the comparison is posed: eta0+ = eta0 (1 - u_fs/D) turns a relative error of D into a
        # relative error of eta0+ (and of the rate) u_fs / |D - u_fs| times as large; near u_fs = D
        # (lead's disordered range in the CD model) the shock all but erases the perturbation
        amp = u_w / abs(D - u_w) if (np.isfinite(u_w) and D != u_w) else math.inf
        eta0p_h = eta0_plus(info["D_table"])
        notes.append(f"Richtmyer's eta0+ = eta0 (1 - u_fs/D) = {eta0p / A:.2f} eta0 amplifies a relative error of D "
                     f"{amp:.1f}-fold (u_fs / |D - u_fs|); with the CD Hugoniot's D "
                     f"({info['D_table'] / units.km_s:.3f} km/s) instead of the measured {D / units.km_s:.3f} km/s, "
                     f"eta0+ = {eta0p_h / units.um:.3g} um")
        jet_from = "valleys" if (np.isfinite(eta_s[-1]) and eta_s[-1] < 0) else "crests"
        notes.append(f"the leading material at the end comes from the {jet_from} (eta, 5-frame mean, "
                     f"{'<' if jet_from == 'valleys' else '>'} 0): "
                     + ("the perturbation has inverted, as in a fluid" if jet_from == "valleys" else
                        "the perturbation has not inverted: the crests run ahead"))
        q["eta_end"] = Quantity(float(eta[-1]) / units.um, "um", note="signed mode amplitude at the end "
                                "(negative: inverted, spikes from the valleys)")
        notes.append(f"perturbation {'inverts' if inverted else 'does not invert'}"
                     + (f" at {t_inv / units.us:.4f} us ({(t_inv - t_start) * k * u_w:.2f} inversion times "
                        f"1/(k u_fs) after the impulse)" if inverted else f" by {t_end / units.us:.2f} us"))
        notes.append("jet tip: foremost cluster of fragments with >= "
                     f"{v.g_tip} clusters; u_fs: mean velocity of the body's {v.fs_layer:g} r0 layer "
                     "below the valley front")
        extra = {"regime": self.regime(pr["ordered"]), "k_eta0": k * A, "t_valley_us": t_valley / units.us,
                 "t_crest_us": t_crest / units.us, "inverted": inverted, "t_inversion_us": t_inv / units.us,
                 "richtmyer_window_us": [t_start / units.us, t_fit / units.us], "n_particles": sm["n"],
                 "n_steps": sm["nsteps"], "particle_steps": sm["n"] * sm["nsteps"], "stepping_time_s": sm["t_run"],
                 "u_drive_km_s": info["u"] / units.km_s, "r0_um": info["r0"] / units.um,
                 "orientation": info["orientation"], "richtmyer_u_fs_km_s": u_w / units.km_s,
                 "richtmyer_D_km_s": D / units.km_s, "d_amplification": amp,
                 "eta0_plus_hugoniot_um": eta0p_h / units.um}
        return q, notes, extra

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        info = sm["info"]
        rec, _ = self.restore(sm)
        jtxt = "off" if v.J is None else f"{v.J:g}"
        title = (f"{v.material} sinusoid {info['amplitude'] / units.um:g} um / {info['wavelength'] / units.um:g} um, "
                 f"{result.quantities['P'].value:.1f} GPa, r0 {info['r0'] / units.um:g} um, J = {jtxt}")
        files = [self.write_summary(out, summaries, "jets")]
        files += self.history_png(out, rec, info, title, "jets")
        files += self.snapshots_png(out, rec, info, title, "jets")
        files += self.eta_png(out, rec, info, result, title)
        return files

    def eta_png(self, out, rec, info, result, title):
        plt = matplotlib_agg()
        t, eta = rec.series("eta")
        ex = result.extra
        t0 = ex["richtmyer_window_us"][0] * units.us
        q = result.quantities
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        ax.plot(t / units.us, eta / units.um, label="eta (cosine mode of the surface)")
        if np.isfinite(q["eta0_plus"].value) and np.isfinite(q["growth_rate"].value):
            tt = np.linspace(t0, ex["richtmyer_window_us"][1] * units.us, 20)
            ax.plot(tt / units.us, q["eta0_plus"].value - q["growth_rate"].reference * units.m_s * (tt - t0) / units.um,
                    "k--", lw=0.9, label="Richtmyer: eta0+ - k eta0+ u_fs t")
        ax.axhline(0, color="grey", lw=0.5)
        ax.axvline(ex["t_crest_us"], color="grey", ls=":", lw=0.8, label="shock at the crests")
        ax.axvline(t0 / units.us, color="grey", ls="--", lw=0.8, label="surface at 0.9 of its final speed")
        ax.set_xlabel("t (us)")
        ax.set_ylabel("eta (um)")
        ax.legend(fontsize=8)
        ax.set_title(title, fontsize=9)
        fig.tight_layout()
        png = out / "jets_eta.png"
        fig.savefig(png, dpi=110)
        plt.close(fig)
        csvp = out / "jets_eta.csv"
        with open(csvp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_us", "eta_um"])
            for a, b in zip(t, eta):
                w.writerow([f"{a / units.us:.6g}", f"{b / units.um:.6g}"])
        return [png, csvp]


register_scene(JetsScene())

__all__ = ["JetsScene", "JET_RATIO_EXPERIMENT"]

"""The fragments of one configuration (:class:`Fragments`) and their spectra: N(g), mass fractions,
the mass distribution, CSV and PNG."""

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import units

__all__ = ["Fragments", "G_MAX", "largest_piece", "write_spectrum_csv", "plot_spectrum"]

#: default largest fragment counted as "small" (dusting, physics of the CD paper 3.1)
G_MAX = 10


@dataclass
class Fragments:
    """The fragments of one configuration (ASE units: Angstrom, amu, ASE time).

    Attributes
    ----------
    labels : (N,) int64
        Fragment of each particle (rows of the Atoms), numbered in order of
        their first particle; -1 for particles left out (``exclude``).
    g : (F,) int64
        Particles per fragment.
    mass : (F,) float64, amu
    com : (F, 3) float64, Angstrom
        Centre of mass, unwrapped through the fragment's bonds and wrapped
        into the box on periodic axes (module docstring).
    velocity : (F, 3) float64, Angstrom / ASE time
        Momentum / mass.
    volume : (F,) float64, Angstrom^3
        Sum of the particle volumes.
    diameter : (F,) float64, Angstrom
        Equivalent diameter ``(6 V / pi)^(1/3)``.
    percolating : (F, 3) bool
        The fragment is bonded to its own image across that periodic axis.
    nbonds : int
        Bonds in the graph (pairs within the bond distance, or linked pairs given).
    bond : str
        How bonds were found: ``"distance b*r0_ab (b=...)"``, ``"linked pairs (MCA state)"``
        or ``"pairs"``.
    b : float or None
        Bond distance as a multiple of r0 (distance bonds).
    step : int or None
        ``atoms.info['step']`` when the Atoms had it.
    time : float or None
        ``atoms.info['time']`` (ASE units) when the Atoms had it.
    meta : dict
        ``timings_s`` (wall time of the pair search, the union-find and the
        per-fragment sums, s) and, for distance bonds, ``npairs_searched``
        (pairs the cell list returned).
    """

    labels: np.ndarray
    g: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    velocity: np.ndarray
    volume: np.ndarray
    diameter: np.ndarray
    percolating: np.ndarray
    nbonds: int = 0
    bond: str = ""
    b: float = None
    step: int = None
    time: float = None
    meta: dict = field(default_factory=dict)

    @property
    def n_fragments(self):
        """Number of fragments F."""
        return len(self.g)

    @property
    def largest(self):
        """Index of the fragment with most particles (the first one on a tie), or -1."""
        return int(np.argmax(self.g)) if len(self.g) else -1

    def spectrum(self):
        """The spectrum N(g): ``(g, N)``, the sizes present (ascending) and their counts."""
        gs, n = np.unique(self.g, return_counts=True)
        return gs, n

    def count(self, g_max=G_MAX):
        """Number of fragments with at most ``g_max`` particles."""
        return int(np.sum(self.g <= g_max))

    def mass_fraction(self, g_max=G_MAX):
        """Mass in fragments of at most ``g_max`` particles / total mass."""
        tot = self.mass.sum()
        return float(self.mass[self.g <= g_max].sum() / tot) if tot > 0 else 0.0

    def mass_distribution(self):
        """Cumulative mass distribution: ``(m, F)``, fragment masses ascending (amu) and the
        fraction of the total mass in fragments of mass <= m."""
        m = np.sort(self.mass)
        tot = m.sum()
        return m, (np.cumsum(m) / tot if tot > 0 else np.zeros_like(m))

    def table(self):
        """Per-fragment rows with units: g, mass (kg), centre (um), velocity (m/s),
        volume (um^3), diameter (um), percolating axes."""
        cols = {"fragment": np.arange(self.n_fragments), "g": self.g, "mass_kg": self.mass / units.kg}
        for d, a in enumerate("xyz"):
            cols[f"com_{a}_um"] = self.com[:, d] / units.um
        for d, a in enumerate("xyz"):
            cols[f"v_{a}_m_s"] = self.velocity[:, d] / units.m_s
        cols["volume_um3"] = self.volume / units.um ** 3
        cols["diameter_um"] = self.diameter / units.um
        cols["percolating"] = ["".join(a for d, a in enumerate("xyz") if p[d]) for p in self.percolating]
        return cols

    def write_csv(self, path):
        """Write :meth:`table` as CSV (header with units); returns the path."""
        path = Path(path)
        cols = self.table()
        names = list(cols)
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            for k in range(self.n_fragments):
                w.writerow([_fmt(cols[c][k]) for c in names])
        return path

    def plot_spectrum(self, path, title=None):
        """N(g) on log-log axes: writes ``path`` (.png) and the CSV beside it (g, N).

        Returns (png path, csv path).
        """
        gs, n = self.spectrum()
        return plot_spectrum(path, gs, n, title or f"{self.n_fragments} fragments, {int(self.g.sum())} particles")

    def plot_mass_distribution(self, path, title=None):
        """Cumulative mass fraction against fragment mass: ``path`` (.png) + CSV (mass in kg).

        Returns (png path, csv path).
        """
        png, csvp = _png_csv(path)
        m, frac = self.mass_distribution()
        _write_columns(csvp, ["mass_kg", "cumulative_mass_fraction"], [m / units.kg, frac])
        fig, ax = _figure()
        ax.step(m / units.kg, frac, where="post")
        ax.set_xscale("log")
        ax.set_xlabel("fragment mass (kg)")
        ax.set_ylabel("mass fraction in fragments of mass <= m")
        ax.set_ylim(0, 1.02)
        ax.set_title(title or f"{self.n_fragments} fragments")
        ax.grid(True, which="both", alpha=0.3)
        fig.savefig(png, dpi=110)
        return png, csvp


def _fmt(v):
    if isinstance(v, (float, np.floating)):
        return f"{v:.8g}"
    return str(v)


def largest_piece(labels, rows):
    """The rows among ``rows`` that lie in the fragment holding most of them (e.g. what is left
    of a plate after an impact: its debris and spall left out).  ``labels`` as
    :attr:`Fragments.labels` (-1, excluded particles, never counts)."""
    rows = np.asarray(rows)
    lab = np.asarray(labels)[rows]
    return rows[lab == np.bincount(lab[lab >= 0]).argmax()]


def write_spectrum_csv(path, gs, n):
    """The spectrum N(g) as CSV (columns g, N); returns the path."""
    _write_columns(path, ["g", "N"], [np.asarray(gs), np.asarray(n)])
    return Path(path)


def plot_spectrum(path, gs, n, title=None):
    """N(g) on log-log axes (sizes ``gs``, counts ``n``, as :meth:`Fragments.spectrum` gives them):
    writes ``path`` (.png) and the CSV beside it (g, N).  Returns (png path, csv path)."""
    png, csvp = _png_csv(path)
    write_spectrum_csv(csvp, gs, n)
    fig, ax = _figure()
    ax.loglog(gs, n, "o")
    ax.set_xlabel("clusters per fragment g")
    ax.set_ylabel("number of fragments N(g)")
    ax.set_title(title or f"{int(np.sum(n))} fragments")
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(png, dpi=110)
    return png, csvp


def _png_csv(path):
    path = Path(path)
    png = path if path.suffix == ".png" else path.with_suffix(".png")
    return png, png.with_suffix(".csv")


def _write_columns(path, names, columns):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        for row in zip(*columns):
            w.writerow([_fmt(v) for v in row])


def _figure():
    # an Agg figure without pyplot: no global backend state is touched
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(5.5, 4.0))
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot(1, 1, 1)


"""Where the energy of a :class:`clusterdyn.md.DampedVerlet` run went: :class:`EnergyLedger`."""

import numpy as np


class EnergyLedger:
    """The energy balance of a run since :meth:`start` (the first :meth:`report` starts it).

    ``kinetic``, ``potential`` (pairs, walls and attached force terms) now; ``drive_work`` (work
    of pistons and tractions on the other particles), ``layer_kinetic`` (the change of the driven
    layers' own kinetic energy), ``damping_loss`` (pair damping), ``wall_dissipated`` (sticking
    walls), ``removed_kinetic`` and ``removed_potential`` (the energy the particles removed outside
    the ``region`` took away) and ``removed_momentum`` ((3,), amu Angstrom / ASE time), all since
    the start; ``energy_in`` = initial kinetic energy + the absolute drive work; ``residual`` =
    change of (kinetic + potential) minus (drive work + layer kinetic - damping loss - wall
    dissipated - removed kinetic - removed potential): zero for an exact integrator, velocity
    Verlet's O(dt^2) error otherwise.  With attached force terms that dissipate (a piece's
    ``dissipated``, e.g. the boundary law's damage and slip), ``term_dissipated`` is booked too.
    """

    def __init__(self, dyn):
        self.dyn = dyn
        #: the values at the start (None: not started)
        self.start_values = None

    def _now(self):
        d = self.dyn
        r = d.removed
        return {"kinetic": d.get_kinetic_energy(), "potential": d.potential_energy, "layers": d._layer_kinetic(),
                "work": d._drive_sum("work"), "dissipated": d._drive_sum("dissipated"),
                "damping_loss": d.damping_loss, "removed_kinetic": r["kinetic"], "removed_potential": r["potential"],
                "removed_px": float(r["momentum"][0]), "removed_py": float(r["momentum"][1]),
                "removed_pz": float(r["momentum"][2]), **self._terms()}

    def _terms(self):
        """The attached force terms' dissipation, only where there are such terms (so a run without
        them keeps its ledger and checkpoint as they were)."""
        terms = [q for q in self.dyn.pieces if q.adds_forces]
        return {"term_dissipated": float(sum(q.dissipated for q in terms))} if terms else {}

    def start(self):
        """Take the present state as the start."""
        if self.dyn.forces is None:
            self.dyn._refresh_properties()
        self.start_values = self._now()

    def report(self):
        """The ledger (a dict, eV; see the class)."""
        if self.start_values is None:
            self.start()
        L0 = self.start_values
        d = self.dyn
        K, U = d.get_kinetic_energy(), d.potential_energy
        work = d._drive_sum("work") - L0["work"]
        layers = d._layer_kinetic() - L0["layers"]
        loss = d.damping_loss - L0["damping_loss"]
        diss = d._drive_sum("dissipated") - L0["dissipated"]
        rk = d.removed["kinetic"] - L0.get("removed_kinetic", 0.0)
        ru = d.removed["potential"] - L0.get("removed_potential", 0.0)
        rp = d.removed["momentum"] - np.array([L0.get("removed_p" + a, 0.0) for a in "xyz"])
        change = K + U - L0["kinetic"] - L0["potential"]
        out = {"kinetic": K, "potential": U, "kinetic0": L0["kinetic"], "potential0": L0["potential"],
               "drive_work": work, "layer_kinetic": layers, "damping_loss": loss, "wall_dissipated": diss,
               "removed_kinetic": rk, "removed_potential": ru, "removed_momentum": rp,
               "energy_in": L0["kinetic"] + abs(work),
               "residual": change - (work + layers - loss - diss - rk - ru)}
        terms = self._terms()
        if terms:
            td = terms["term_dissipated"] - L0.get("term_dissipated", 0.0)
            out["term_dissipated"] = td
            out["residual"] = change - (work + layers - loss - diss - rk - ru - td)
        return out

"""The energy error of a run driven by pistons: ``E - E(0) - W`` after every step.

``clusterdyn study stability`` measures the time-step limit with it (a run is bounded while the
error stays small); the tests of extreme pistons check the energy balance with it.  Energies in eV.
"""

import math


class EnergyBalance:
    """Observer: energy error ``E - E(0) - W`` after every step (attach with interval 1).

    ``W`` is the work the pistons have done on the sample since the first
    call (:attr:`clusterdyn.md.Piston.work`, the trapezoid integral of
    ``-force . U`` over the steps); constant-velocity pistons keep their own
    kinetic energy, so ``E - E(0) - W`` is the integrator's error.
    """

    def __init__(self, dyn, atoms, pistons):
        self.dyn, self.atoms, self.pistons = dyn, atoms, pistons
        self.E0 = None
        self.W0 = 0.0
        self.errors = []
        self.min_r = math.inf

    @property
    def W(self):
        """Work of the pistons since the first call, eV."""
        return sum(p.work for p in self.pistons) - self.W0

    def __call__(self):
        dyn = self.dyn
        E = dyn.get_total_energy()
        W = sum(p.work for p in self.pistons)
        if self.E0 is None:
            self.E0, self.W0 = E, W
        self.errors.append(E - self.E0 - (W - self.W0))
        st = dyn.calc.last_stats
        if st is not None:
            self.min_r = min(self.min_r, st["min_r_over_r0"])

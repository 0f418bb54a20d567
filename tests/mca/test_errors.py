"""Bad input gives clear errors; stiff and extreme cases run or stop naming the limit."""

import numpy as np
import pytest

from clusterdyn.errors import InputError, InstabilityError
from clusterdyn.materials import get_material
from clusterdyn.build.mca import mca_packing
from clusterdyn.mca.calculator import MCA
from clusterdyn.mca.dynamics import MCADynamics, default_timestep
from clusterdyn.materials.mca import mca_material
from clusterdyn.analysis.mca_elastic import elastic_material


def test_library_through_get_material():
    for name in ("alumina", "concrete", "Al6061", "copper"):
        m = get_material(name)
        assert m.E > 0 and m.source


@pytest.mark.parametrize("nu", [0.5, 0.6, -1.0, -1.5])
def test_bad_poisson(nu):
    with pytest.raises(InputError, match="nu"):
        mca_material("x", 2.0, 100.0, nu, response="elastic")


def test_negative_modulus():
    with pytest.raises(InputError, match="E"):
        mca_material("x", 2.0, -100.0, 0.2, response="elastic")


def test_sigma_c_below_sigma_t():
    with pytest.raises(InputError, match="sigma_c"):
        mca_material("x", 2.0, 100.0, 0.2, sigma_t_GPa=1.0, sigma_c_GPa=0.5)


def test_unknown_packing():
    with pytest.raises(InputError, match="packing"):
        mca_packing(elastic_material(0.2), 1.0, (4, 4, 4), "bcc")


def test_2d_call_on_3d_sample():
    atoms = mca_packing(elastic_material(0.2), 1.0, (4, 4, 4), "fcc")
    atoms.calc = MCA(dim=2)
    with pytest.raises(InputError, match="plane strain"):
        atoms.get_forces()


def test_timestep_above_limit_names_it():
    atoms = mca_packing(elastic_material(0.2), 1.0, (4, 4, 4), "fcc")
    atoms.calc = MCA()
    with pytest.raises(InstabilityError, match="limit"):
        MCADynamics(atoms, timestep=5 * default_timestep(atoms))


def _shake(atoms, steps=300):
    atoms.calc = MCA()
    atoms.calc.setup(atoms)
    rng = np.random.default_rng(0)
    from clusterdyn.mca.dynamics import wave_speeds
    atoms.set_velocities(rng.normal(size=atoms.positions.shape) * 1e-3 * wave_speeds(elastic_material(0.25))[0])
    dyn = MCADynamics(atoms)
    e0 = dyn.total_energy()
    dyn.run(steps)
    assert np.isfinite(atoms.positions).all()
    assert abs(dyn.total_energy() - e0) < 1e-2 * abs(e0)


def test_nu_049_stable_at_default_step():
    _shake(mca_packing(elastic_material(0.49), 1.0, (4, 4, 4), "fcc"))


def test_two_phases_100_to_1_stable():
    soft = elastic_material(0.25, E_GPa=10.0)
    hard = elastic_material(0.25, E_GPa=1000.0)
    atoms = mca_packing(None, 1.0, (6, 4, 4), "fcc", materials=[soft, hard],
                        material_id=lambda p: (p[:, 0] > 3.0).astype(int))
    _shake(atoms)

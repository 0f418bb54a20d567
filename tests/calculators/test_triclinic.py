"""Triclinic periodic cells are refused in one line, before any work, and leave no strained cell
behind (#46 item 9; docs/ase_users.md, "Triclinic cells")."""

import numpy as np
import pytest
from ase.build import bulk
from ase.filters import FrechetCellFilter
from ase.optimize import FIRE

from clusterdyn.build.lattice import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError

R0 = 5.0e4


def _one_line(exc):
    assert "\n" not in str(exc.value) and "orthorhombic" in str(exc.value)


def test_a_primitive_bulk_cell_is_refused_with_the_cell_unchanged():
    a = bulk("Al", "fcc", a=np.sqrt(2) * R0)           # primitive: triclinic, periodic
    a.info["cd_materials"], a.info["cd_r0"] = ["Al"], [R0]
    cell, pos = a.cell.array.copy(), a.positions.copy()
    a.calc = ClusterDynamics()
    with pytest.raises(InputError) as e:
        a.get_potential_energy()
    _one_line(e)
    np.testing.assert_array_equal(a.cell.array, cell)
    np.testing.assert_array_equal(a.positions, pos)


def test_numerical_stress_is_refused_before_the_cell_is_touched():
    a = fcc_packing("Al", R0, (3, 3, 3), pbc=True)
    a.calc = ClusterDynamics()
    cell = a.cell.array.copy()
    with pytest.raises(InputError, match="get_stress"):
        a.calc.calculate_numerical_stress(a)
    np.testing.assert_array_equal(a.cell.array, cell)
    assert np.isfinite(a.get_stress()).all()           # the analytic stress is there


def test_a_cell_filter_step_that_shears_is_undone():
    a = fcc_packing("Al", R0, (3, 3, 3), pbc=True)
    a.rattle(0.01 * R0, seed=1)
    a.calc = ClusterDynamics()
    c0 = a.cell.array.copy()
    opt = FIRE(FrechetCellFilter(a), logfile=None)
    with pytest.raises(InputError) as e:
        opt.run(steps=20)
    _one_line(e)
    cell, pos, _ = a.calc._last_box                     # the last calculation's
    np.testing.assert_array_equal(a.cell.array, cell)
    np.testing.assert_array_equal(a.positions, pos)
    off = a.cell.array - np.diag(np.diag(a.cell.array))
    assert np.abs(off).max() <= 1e-10 * np.abs(a.cell.array).max()
    assert np.isfinite(a.get_potential_energy())        # the calculator takes the Atoms again

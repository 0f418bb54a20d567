"""N steps + checkpoint + restart + N steps equals 2N steps bit for bit (damped, with a piston)."""

import subprocess
import sys
import textwrap

import numpy as np

from clusterdyn import units
from clusterdyn.io.checkpoint import load_run, save_run
from clusterdyn.scenes.shock import build_shock

N = 150


def make():
    s = build_shock(size=(12, 3, 3), u=2 * units.km_s, J=50, seed=3)
    return s.atoms, s.dyn


def test_restart_is_bit_identical(tmp_path):
    a, d = make()
    d.run(2 * N)
    b, e = make()
    e.run(N)
    path = tmp_path / "state.h5"
    save_run(path, e, extra={"note": "half way"})
    del b, e
    c, f, extra = load_run(path)
    assert extra["note"] == "half way" and f.nsteps == N and f.J == 50
    f.run(N)
    assert f.nsteps == 2 * N
    assert np.array_equal(c.positions, a.positions)
    assert np.array_equal(c.get_momenta(), a.get_momenta())
    assert np.array_equal(c.constraints[0].force, a.constraints[0].force)


def test_restart_in_a_new_process_is_bit_identical(tmp_path):
    a, d = make()
    d.run(2 * N)
    b, e = make()
    e.run(N)
    save_run(tmp_path / "state.h5", e)
    code = textwrap.dedent(f"""
        import numpy as np
        from clusterdyn.io.checkpoint import load_run
        atoms, dyn, _ = load_run({str(tmp_path / 'state.h5')!r})
        dyn.run({N})
        np.save({str(tmp_path / 'pos.npy')!r}, atoms.positions)
        np.save({str(tmp_path / 'mom.npy')!r}, atoms.get_momenta())
    """)
    subprocess.run([sys.executable, "-c", code], check=True, timeout=300)
    assert np.array_equal(np.load(tmp_path / "pos.npy"), a.positions)
    assert np.array_equal(np.load(tmp_path / "mom.npy"), a.get_momenta())

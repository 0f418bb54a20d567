"""ASE routes to clusterdyn runs (#46 item 12): ase.io.read of H5MD through ASE's ``ase.ioformats``
entry point, and DampedVerlet(trajectory=) frames with energy, forces and material ids."""

import os
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest
from ase.io import read

from clusterdyn.build.lattice import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.io import H5MDWriter, read_h5md
from clusterdyn.md import DampedVerlet

ROOT = Path(__file__).resolve().parents[2]
R0 = 5.0e4


def _two_materials():
    a = fcc_packing("Al", R0, (3, 3, 3))
    mid = (a.positions[:, 0] > a.positions[:, 0].mean()).astype(np.int64)
    a.arrays["material"][:] = mid
    a.info["cd_materials"], a.info["cd_r0"] = ["Al", "Pb"], [R0, R0]
    a.calc = ClusterDynamics()
    a.calc.setup(a)
    a.set_masses(np.array([p.mass for p in a.calc.potentials])[mid])
    a.set_velocities(np.random.default_rng(0).normal(0, 2e-3, (len(a), 3)))
    return a


def test_damped_verlet_trajectory_frames_restore_a_two_material_sample(tmp_path):
    a = _two_materials()
    path = tmp_path / "run.traj"
    dyn = DampedVerlet(a, trajectory=str(path), loginterval=5)
    dyn.run(10)
    dyn.close()
    frames = read(path, ":")
    assert len(frames) == 3
    last = frames[-1]
    e, f = last.get_potential_energy(), last.get_forces()
    assert np.abs(f).max() > 0
    np.testing.assert_array_equal(last.get_tags(), a.arrays["material"])
    # a new calculator on the frame alone (no arguments, no material array): the same energy and
    # conservative forces, which it would not give with one material for all
    back = last.copy()
    back.calc = ClusterDynamics()
    assert back.get_potential_energy() == pytest.approx(e, rel=1e-12)
    np.testing.assert_allclose(back.get_forces(), f, rtol=1e-9, atol=1e-12 * np.abs(f).max())
    one = last.copy()
    one.set_tags(0)
    one.calc = ClusterDynamics()
    assert abs(one.get_potential_energy() - e) > 1e-3 * abs(e)


def test_ase_io_read_h5md_through_the_entry_point(tmp_path):
    a = _two_materials()
    path = tmp_path / "run.h5md"
    dyn = DampedVerlet(a)
    with H5MDWriter(path, a, dyn=dyn) as w:
        dyn.attach(w, interval=5)
        dyn.run(10)
    # the entry point as pyproject.toml declares it, in a distribution on a temporary path
    ep = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["ase.ioformats"]
    from importlib.metadata import entry_points
    installed = {e.name: e.value for e in entry_points(group="ase.ioformats") if e.name in ep}
    if installed:       # clusterdyn installed (not only on the path): its own entry point, as declared
        assert installed == ep
    else:               # a distribution on a temporary path that declares it
        dist = tmp_path / "site" / "clusterdyn_ep-0.dist-info"
        dist.mkdir(parents=True)
        (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: clusterdyn-ep\nVersion: 0\n")
        (dist / "entry_points.txt").write_text("[ase.ioformats]\n" + "".join(f"{k} = {v}\n" for k, v in ep.items()))
    code = textwrap.dedent(f"""
        import numpy as np, ase.io
        frames = ase.io.read({str(path)!r}, ':')
        last = ase.io.read({str(path)!r})
        every2 = ase.io.read({str(path)!r}, '::2')
        np.savez({str(tmp_path / 'out.npz')!r}, n=len(frames), n2=len(every2), pos=last.positions,
                 mat=last.arrays['material'], e=last.get_potential_energy(), step=last.info['step'])
    """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(tmp_path / "site")]))
    r = subprocess.run([sys.executable, "-W", "error::UserWarning", "-c", code], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    got = np.load(tmp_path / "out.npz")
    ref = read_h5md(path)
    assert int(got["n"]) == 3 and int(got["n2"]) == 2 and int(got["step"]) == 10
    np.testing.assert_array_equal(got["pos"], ref.positions)
    np.testing.assert_array_equal(got["mat"], ref.arrays["material"])
    assert float(got["e"]) == ref.get_potential_energy()

"""h5md_info / format_info: the summary behind ``clusterdyn info FILE``."""

import json

import pytest

from cdio_helpers import make_atoms
from clusterdyn.errors import InputError
from clusterdyn.io import H5MDWriter, format_info, h5md_info, read_h5md


def test_h5md_info(md_file):
    path, atoms, dyn, rec = md_file
    d = h5md_info(path)
    json.dumps(d)                                        # JSON-able (for --json)
    assert d["n_frames"] == 6 and d["n_particles"] == len(atoms)
    assert (d["first_step"], d["last_step"]) == (0, 10)
    assert d["time_start_ps"] == 0.0
    assert d["time_end_ps"] == pytest.approx(0.020, rel=1e-12)   # 10 steps of 2 fs
    assert d["pbc"] == [True, True, True]
    assert d["series"] == ["position", "velocity", "force", "species", "mass", "box/edges"]
    assert set(d["per_particle"]) == {"id", "material"}
    assert set(d["observables"]) == {"dt", "kinetic_energy", "potential_energy", "total_energy"}
    assert d["units"]["force"] == "kJ mol-1 Angstrom-1"
    assert d["creator"]["name"] == "clusterdyn"
    assert d["description"]["md-type"] == "VelocityVerlet"
    assert d["parameters"]["r0"] == 5.0


def test_format_info(md_file):
    path, atoms, dyn, rec = md_file
    text = format_info(path)
    assert "frames:       6 (steps 0 .. 10)" in text
    assert "particles:    32 in particles/trajectory, pbc TTT" in text
    assert "0.02 ps" in text
    assert "potential_energy" in text and "kJ mol-1" in text
    # a sample's energy also in J: the kJ/mol figure converted exactly
    import re
    from ase import units
    from clusterdyn.io import H5MDReader
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("potential_energy"))
    kj, joule = map(float, re.match(r"\s*potential_energy\s+(\S+) kJ mol-1 \((\S+) J\)", line).groups())
    with H5MDReader(path) as r:
        last = float(r.get_observable("potential_energy")[2][-1])
    assert kj == float(f"{last:.6g}")
    assert abs(joule / (last * units.kJ / units.mol / units.J) - 1) < 1e-5
    assert "VelocityVerlet, timestep 2 fs" in text


def test_info_of_empty_and_missing_files(tmp_path):
    path = tmp_path / "empty.h5md"
    H5MDWriter(path, make_atoms()).close()               # a run that has not written yet
    d = h5md_info(path)
    assert d["n_frames"] == 0 and d["first_step"] is None
    assert "frames:       0" in format_info(path)
    with pytest.raises(InputError, match="no frames"):
        read_h5md(path)
    with pytest.raises(InputError, match="file not found"):
        format_info(tmp_path / "nope.h5md")


def test_a_drives_records_are_labelled_as_the_files_start():
    """A drive's description is written when the file opens: its impulse and work read 0 there, and
    info says so instead of printing 0 beside the run's force."""
    from clusterdyn.io.info import _metadata_lines
    meta = {"constraints": [{"kind": "Piston", "impulse_N_s": [0.0, 0.0, 0.0], "work_J": 0.0,
                             "n_particles": 4}]}
    line = next(ln for ln in _metadata_lines(meta) if ln.startswith("drives:"))
    assert "impulse_N_s=[0.0, 0.0, 0.0] (at the file's start" in line
    assert "work_J=0.0 (at the file's start" in line and "kind=Piston," in line

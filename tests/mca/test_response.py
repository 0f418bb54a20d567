"""Response functions: plastic plateau and residual strain, degrading unloading modulus, healing."""

import numpy as np

from clusterdyn.materials import get_material
from clusterdyn.build.mca import precrack
from clusterdyn.scenes.mca_experiments import uniaxial
from clusterdyn.scenes.mca_material_point import load_unload_reload


def test_elastic_plastic_plateau_and_residual_strain():
    al = get_material("Al6061")
    ey = al.sigma_y / al.E
    em = 4 * ey

    def path(s):                       # load to 4 eps_y, unload by eps_y (to about zero stress)
        return s / 0.6 if s <= 0.6 else 1 - (s - 0.6) / 0.4 * (ey / em)

    r = uniaxial(al, "tension", size=(10, 4, 4), strain_max=em, steps=2000, path=path, damping=0.1)
    e, s = r["strain"], r["stress"]
    k = int(np.argmax(e))
    plateau = s[:k][e[:k] > 2 * ey]
    assert abs(plateau.mean() / al.sigma_y - 1) < 0.05
    assert abs(s[-1]) < 0.15 * al.sigma_y                  # unloaded
    assert e[-1] > 2 * ey                                  # residual (plastic) strain


def test_hardening_table():
    al = get_material("Al6061")
    H = 0.1 * al.E
    mat = al.replace(hardening=[[0.0, 1.0], [al.sigma_y, al.sigma_y + H]])
    ey = al.sigma_y / al.E
    r = uniaxial(mat, "tension", size=(10, 4, 4), strain_max=5 * ey, steps=1500, damping=0.1)
    e, s = r["strain"], r["stress"]
    late = (e > 3 * ey)
    slope = np.polyfit(e[late], s[late], 1)[0]
    assert 0.3 * H < slope < 1.2 * H                       # hardening, not a plateau


def test_degrading_unloading_modulus(tmp_path):
    co = get_material("concrete")
    em = 0.95 * co.sigma_t / co.E

    r = uniaxial(co, "tension", size=(10, 4, 4), strain_max=em, steps=2500, path=load_unload_reload,
                 damping=0.1)
    e, s = r["strain"], r["stress"]
    n = len(e)
    E0 = np.polyfit(e[int(.1 * n):int(.25 * n)], s[int(.1 * n):int(.25 * n)], 1)[0]
    E1 = np.polyfit(e[int(.45 * n):int(.55 * n)], s[int(.45 * n):int(.55 * n)], 1)[0]
    assert abs(E0 / co.E - 1) < 0.05
    assert E1 < 0.8 * E0
    from matplotlib import use
    use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ax.plot(e * 1e3, s / co.sigma_t)
    ax.set_xlabel("strain (1e-3)")
    ax.set_ylabel("stress / sigma_t")
    fig.savefig(tmp_path / "degrading-cycle.png")
    plt.close(fig)
    assert (tmp_path / "degrading-cycle.png").stat().st_size > 0


def _press_and_pull(sigma_weld):
    mat = get_material("alumina")
    mat = mat.replace(extra={**mat.extra, "sigma_weld": sigma_weld, "n_weld": 20})

    def prep(atoms):                   # two fragments: every pair across the mid-plane unlinked
        precrack(atoms, point=atoms.cell.diagonal() / 2, normal=(1, 0, 0))

    def path(s):                       # press (to ~ -0.5 sigma_t) and release, then pull
        return -np.sin(2 * np.pi * s) ** 2 if s < 0.5 else (s - 0.5) / 0.5

    r = uniaxial(mat, "tension", size=(8, 4, 4), strain_max=0.5 * mat.sigma_t / mat.E, steps=1500,
                 path=path, damping=0.1, prepare=prep)
    return mat, r


def test_healing_above_threshold_carries_tension():
    mat, r = _press_and_pull(0.05 * get_material("alumina").sigma_t)
    assert r["stress"].min() < -0.3 * mat.sigma_t
    assert r["stress"][-1] > 0.3 * mat.sigma_t


def test_no_healing_below_threshold():
    mat, r = _press_and_pull(10 * get_material("alumina").sigma_t)
    assert r["stress"].min() < -0.3 * mat.sigma_t
    assert abs(r["stress"][-1]) < 0.05 * mat.sigma_t

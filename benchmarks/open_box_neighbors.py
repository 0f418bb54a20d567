"""The cell list in an open box whose bounding box grows (a debris cloud): memory and build time per frame.

    python benchmarks/open_box_neighbors.py RUN.h5md [--repeats 3]

For every frame of an H5MD file of an impact run (e.g. ``clusterdyn run
hypervelocity --out DIR``), builds the CD calculator's neighbour list (sorted,
half, skin as the calculator's) from scratch and prints: the bounding box
volume over the volume the clusters fill (N r0^3/sqrt 2), the grid (cells
along each axis, cells per particle, whether it was coarsened), the pairs,
the bytes held by the list and its work arrays, and the best build time.
"""

import argparse
import math
import time

import numpy as np

from clusterdyn import units
from clusterdyn.io import H5MDReader
from clusterdyn.neighbors import NeighborList
from clusterdyn.neighbors.celllist import MAX_CELLS_PER_PARTICLE


def nbytes(nl):
    arrays = [nl.first_n, nl.j_p, nl.img_p, nl.perm_n, nl.offs_nc, nl.ref_nc] + list(nl._work.values())
    return sum(a.nbytes for a in arrays if a is not None)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("h5md")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    with H5MDReader(a.h5md) as r:
        calc = r.calculator()
        first = r.get_atoms(0)
        calc.setup(first)
        cutoff, skin = calc.nl.cutoff, calc.nl.skin
        r0 = min(first.info["cd_r0"])
        print(f"{r.n_particles} particles, cutoff {cutoff / r0:.3f} r0, skin {skin / r0:.3f} r0, "
              f"grid capped at {MAX_CELLS_PER_PARTICLE} cells per particle")
        print("frame  t_us  bbox/filled  cells(x,y,z)  cells/particle  pairs/particle  MB  build_s")
        for f in range(r.n_frames):
            at = r.get_atoms(f)
            pos = at.positions
            nl = NeighborList(cutoff, skin, half=True, sort=True, centered=True)
            best = math.inf
            for _ in range(a.repeats):
                t0 = time.perf_counter()
                nl.build(pos, np.eye(3), np.zeros(3, bool))
                best = min(best, time.perf_counter() - t0)
            ext = np.ptp(pos, axis=0)
            rc = cutoff + skin
            ncell = np.array([max(1, int(math.floor(e / rc))) for e in ext])
            natural = int(np.prod(ncell))
            while ncell.prod() > MAX_CELLS_PER_PARTICLE * len(pos) + 27:      # as NeighborList._grid
                big = int(np.argmax(ncell))
                ncell[big] = max(1, ncell[big] // 2)
            filled = len(pos) * r0 ** 3 / math.sqrt(2)
            coarse = f" (coarsened from {natural} cells)" if natural > ncell.prod() else ""
            print(f"{f:5d} {r.times[f] / units.us:6.2f} {np.prod(ext) / filled:11.1f}  "
                  f"{'x'.join(map(str, ncell))}{coarse}"
                  f"  {ncell.prod() / len(pos):6.2f}  {nl.npairs / len(pos):6.2f}  {nbytes(nl) / 1e6:7.1f}  {best:.3f}")

if __name__ == "__main__":
    main()

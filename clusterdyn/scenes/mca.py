"""MCA scenes (mca-tension, mca-compression) live in :mod:`clusterdyn.mca.scenes`."""

from ..mca import scenes  # noqa: F401  (registers the scenes)

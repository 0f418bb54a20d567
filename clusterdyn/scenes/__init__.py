"""Ready experiments.  Each scene module registers itself with :func:`register`."""

import importlib

from .base import SCENES, Param, Quantity, Scene, SceneResult, get_scene, register

#: scene modules, imported on first use (each adds its scenes to SCENES)
SCENE_MODULES = ["shock", "plate_impact", "mca"]


def _load_all():
    for m in SCENE_MODULES:
        importlib.import_module(f"{__name__}.{m}")
    return SCENES


def all_scenes():
    return _load_all()


__all__ = ["Param", "Quantity", "Scene", "SceneResult", "register", "get_scene", "SCENES",
           "all_scenes", "SCENE_MODULES"]

"""Ready experiments.  Each scene module registers itself with :func:`register`."""

from .base import SCENE_MODULES, SCENES, Param, Quantity, Scene, SceneResult, all_scenes, get_scene, register

__all__ = ["Param", "Quantity", "Scene", "SceneResult", "register", "get_scene", "SCENES",
           "all_scenes", "SCENE_MODULES"]

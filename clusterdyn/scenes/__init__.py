"""Ready experiments.  Each scene module registers its :class:`~clusterdyn.scenes.lifecycle.SceneDef`
instances with :func:`~clusterdyn.scenes.base.register_scene`."""

from .base import (SCENE_MODULES, SCENES, Param, Quantity, SceneResult, all_scenes, get_scene,
                   register_scene)

__all__ = ["Param", "Quantity", "SceneResult", "register_scene", "get_scene", "SCENES",
           "all_scenes", "SCENE_MODULES"]

"""Engine adapters, one module per engine, loaded only when used (style.md, pattern 1).

The core never imports an engine: the registry names adapters as strings.
"""
from __future__ import annotations

import importlib.util

#: registry key = pip extra = engine name -> "module:Class"
ENGINES: dict[str, str] = {
    "mujoco": "impactval.engines.mujoco_:MujocoAdapter",
    "pybullet": "impactval.engines.pybullet_:PybulletAdapter",
    "exudyn": "impactval.engines.exudyn_:ExudynAdapter",
    "mujoco-warp": "impactval.engines.mujoco_warp_:MujocoWarpAdapter",
    "newton": "impactval.engines.newton_:NewtonAdapter",
}
#: the Python module each engine needs
ENGINE_MODULES: dict[str, str] = {"mujoco": "mujoco", "pybullet": "pybullet", "exudyn": "exudyn",
                                  "mujoco-warp": "mujoco_warp", "newton": "newton"}


def engine_status() -> dict[str, str]:
    """"ok" or "not installed: <install command>" for each registered engine, without importing it."""
    return {n: "ok" if importlib.util.find_spec(m) else f"not installed: pip install 'impactval[{n}]'"
            for n, m in ENGINE_MODULES.items()}

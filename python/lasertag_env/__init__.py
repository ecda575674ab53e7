"""lasertag as a PettingZoo / Gymnasium research environment: in-process (the package's
native engine, the default) or over a server's HTTP API.

- :func:`parallel_env`: a PettingZoo ``ParallelEnv``, one agent per robot.
- :func:`vector_env`: many in-process worlds as one Gymnasium ``VectorEnv`` of their
  robots, stepped in one call over every core.
- :func:`single_agent_env`: a Gymnasium ``Env`` controlling one robot
  (also ``gymnasium.make("lasertag/Lasertag-v0", ...)``).
- :class:`LocalServer`: a ``lasertag serve`` child process, to share between environments.

The manual is docs/research.md in the repository.
"""

from __future__ import annotations

import gymnasium

from .client import ServerError
from .native import SHIPPED_MAPS, LasertagVectorEnv, NativeParallelEnv, shipped_map, vector_env
from .observation import ObservationLayout
from .parallel import DEFAULT_REWARDS, LasertagParallelEnv, parallel_env
from .server import BinaryNotFound, LocalServer, find_binary
from .single import LasertagEnv, single_agent_env

__all__ = [
    "parallel_env",
    "vector_env",
    "NativeParallelEnv",
    "LasertagVectorEnv",
    "SHIPPED_MAPS",
    "shipped_map",
    "single_agent_env",
    "LasertagParallelEnv",
    "LasertagEnv",
    "LocalServer",
    "ObservationLayout",
    "ServerError",
    "BinaryNotFound",
    "DEFAULT_REWARDS",
    "find_binary",
]

__version__ = "0.1.0"

if "lasertag/Lasertag-v0" not in gymnasium.registry:
    gymnasium.register("lasertag/Lasertag-v0", entry_point="lasertag_env.single:LasertagEnv")

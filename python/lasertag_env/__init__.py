"""lasertag as a PettingZoo / Gymnasium research environment, over the server's HTTP API.

- :func:`parallel_env`: a PettingZoo ``ParallelEnv``, one agent per robot.
- :func:`single_agent_env`: a Gymnasium ``Env`` controlling one robot
  (also ``gymnasium.make("lasertag/Lasertag-v0", ...)``).
- :class:`LocalServer`: a ``lasertag serve`` child process, to share between environments.

The manual is docs/research.md in the repository.
"""

from __future__ import annotations

import gymnasium

from .client import ServerError
from .observation import ObservationLayout
from .parallel import DEFAULT_REWARDS, LasertagParallelEnv, parallel_env
from .server import BinaryNotFound, LocalServer, find_binary
from .single import LasertagEnv, single_agent_env

__all__ = [
    "parallel_env",
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

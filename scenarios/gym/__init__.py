"""The gymnasium side: the environment ``WarehouseMapUpdate-v0`` (``env``), its episode
bookkeeping and reward (``episode``), and the policies that drive it (``policies``).

Importing this package registers the environment, as Gymnasium documents for third-party
environments; ``gymnasium.make("scenarios.gym:WarehouseMapUpdate-v0")`` imports it on the way.
The environment's module itself (pymunk, the session machinery) loads at the first ``make``.
"""

import gymnasium

ENV_ID = "WarehouseMapUpdate-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="scenarios.gym.env:WarehouseMapUpdateEnv")

"""The gymnasium side: the environment ``WarehouseMapUpdate-v0`` (``env``), its episode
bookkeeping and reward (``episode``), and the policies that drive it (``policies``). ``env`` is
the only module of the project that imports gymnasium; importing this package does not."""

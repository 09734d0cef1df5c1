"""The values of an occupancy grid's cells (ROS convention), defined here once.

The numba kernels import these too: numba reads a module's int globals as compile-time
constants, so ``cell == OCCUPIED`` costs no more in a kernel than ``cell == 100``. Its cache
notices changes to a kernel's own file only, so a value changed here needs the kernels'
``__pycache__`` cleared.
"""

FREE = 0
OCCUPIED = 100
UNKNOWN = -1

"""Monte Carlo localisation (AMCL's filter, nav2's defaults) on an occupancy grid.

Imports only ``gridmap``: it runs on recorded data as well as in the simulator.
"""

from .config import LocalizationError, LocalizerConfig
from .estimate import Estimate
from .localizer import MonteCarloLocalizer

__all__ = ["Estimate", "LocalizationError", "LocalizerConfig", "MonteCarloLocalizer"]

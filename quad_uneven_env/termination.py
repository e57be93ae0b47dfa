"""When an episode ends in a fall: the checks of :class:`~quad_uneven_env.config.TerminationLimits`, in order."""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.config import TerminationLimits


class FallCheck:
    """The fall conditions of one env; :meth:`reason` runs every control step.

    :param limits: the thresholds.
    """

    def __init__(self, limits: TerminationLimits) -> None:
        self.limits = limits
        self._cos_max_tilt = math.cos(math.radians(limits.max_tilt_deg))
        self.inside_xy = (-math.inf, math.inf, -math.inf, math.inf)
        """(xmin, xmax, ymin, ymax) m: the base must stay strictly inside (set per terrain at reset)."""

    def reason(self, base_W: np.ndarray, ground: float, R_WB: np.ndarray, trunk_contact: bool) -> str | None:
        """Why the episode ends, or None.

        :param base_W: (3,) trunk origin, world frame (m).
        :param ground: terrain height under the trunk origin (m).
        :param R_WB: (3, 3) trunk orientation.
        :param trunk_contact: the trunk touches the terrain.
        """
        lim = self.limits
        height = base_W[2] - ground
        if lim.trunk_contact and trunk_contact:
            return "fall: trunk touched the terrain"
        if height < lim.min_base_height:
            return f"fall: base height {height:.3f} m < {lim.min_base_height} m"
        if height > lim.max_base_height:
            return f"fall: base height {height:.3f} m > {lim.max_base_height} m"
        if R_WB[2, 2] < self._cos_max_tilt:
            tilt = np.rad2deg(np.arccos(np.clip(R_WB[2, 2], -1, 1)))
            return f"fall: tilt {tilt:.1f} deg > {lim.max_tilt_deg} deg"
        xmin, xmax, ymin, ymax = self.inside_xy
        if not (xmin < base_W[0] < xmax and ymin < base_W[1] < ymax):
            return "left the terrain"
        return None

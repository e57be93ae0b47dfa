"""The env's renderer: frames from the tracking camera (``rgb_array``, ``depth_array``) or a window (``human``).

Gymnasium's :class:`~gymnasium.envs.mujoco.mujoco_rendering.MujocoRenderer`, opened at the first frame; the
terrain's height field is uploaded to its GL context whenever the env generates a new one.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from quad_uneven_env import constants as C

RENDER_MODES = ("human", "rgb_array", "depth_array")
"""Allowed ``render_mode`` of the env."""


def display_missing(render_mode: str | None) -> bool:
    """True when ``render_mode="human"`` cannot open a window here (Linux without ``DISPLAY``/``WAYLAND_DISPLAY``).

    Asked before any window or GLFW code: without a display GLFW aborts the process instead of raising.
    """
    if render_mode != "human" or not sys.platform.startswith("linux"):
        return False
    return not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class SceneRenderer:
    """Renders ``model``/``data`` in ``render_mode`` at ``width`` x ``height`` px; ``hfield`` is the terrain's id."""

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, render_mode: str | None, width: int, height: int, hfield: int
    ) -> None:
        self.model, self.data = model, data
        self.render_mode = render_mode
        self.width, self.height = width, height
        self.hfield = hfield
        vis = model.vis.global_
        vis.offwidth, vis.offheight = max(vis.offwidth, width), max(vis.offheight, height)
        self._renderer = None
        self._warned_no_display = False

    def __getstate__(self) -> dict[str, Any]:
        """Pickle and ``copy.deepcopy``: without the GL context (a copy opens its own at its first frame)."""
        return dict(self.__dict__, _renderer=None)

    def upload_terrain(self) -> None:
        """Send the model's height field to the open GL contexts (after the env generated a terrain)."""
        if self._renderer is None:
            return
        for viewer in self._renderer._viewers.values():
            viewer.make_context_current()
            mujoco.mjr_uploadHField(self.model, viewer.con, self.hfield)

    def render(self) -> np.ndarray | None:
        """A frame (``rgb_array``: (height, width, 3) uint8; ``depth_array``: (height, width)) or None (``human``,
        or no ``render_mode``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode to gym.make")
            return None
        if self._renderer is None:
            if display_missing(self.render_mode):
                if not self._warned_no_display:
                    gym.logger.warn(
                        "render_mode='human' needs a display, but neither DISPLAY nor WAYLAND_DISPLAY is set: no "
                        "window is opened; use render_mode='rgb_array' (offscreen) on a headless machine"
                    )
                    self._warned_no_display = True
                return None
            from gymnasium.envs.mujoco.mujoco_rendering import MujocoRenderer

            self._renderer = MujocoRenderer(
                self.model, self.data, width=self.width, height=self.height, camera_name=C.TRACK_CAMERA
            )
            self._renderer._get_viewer(self.render_mode)
            self.upload_terrain()
        return self._renderer.render(self.render_mode)

    def close(self) -> None:
        """Release the GL context (a later frame opens a new one)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

"""The scene's cameras and their capture path, built once per trainer and handed to whatever needs them (the
path clearance and floaters, the binocular partner, the path consistency, the methods).

The capture path is ``warpgs.pseudo.trajectory.path_trajectories`` of the input views in the order
``pseudo.trajectory.order``: the spline through their centres cut into segments between neighbours. Each
segment count (and centre kind) is computed once and kept."""

from __future__ import annotations

import numpy as np
import torch


class SceneCameras:
    """``views``: the scene's input cameras (numpy); ``train`` / ``test``: the input and test views on the device;
    ``viewmats`` [N, 4, 4] and ``names`` of the inputs; ``trajectories(frames)``: the capture path."""

    def __init__(self, scene, device, order="nearest"):
        self.views = list(scene.train)
        self.train = [c.to_torch(device) for c in scene.train]
        self.test = [c.to_torch(device) for c in scene.test]
        self.device = device
        self.order = order
        self.viewmats = np.stack([np.asarray(c.viewmat, np.float64) for c in self.views])
        self.names = [c.name for c in self.views]
        self._paths: dict = {}

    def trajectories(self, frames: int, centres: str = "spline") -> list:
        """The path's trajectories, ``frames`` poses each (``path_trajectories``), computed once."""
        from warpgs.pseudo.trajectory import path_trajectories

        key = (frames, centres)
        if key not in self._paths:
            self._paths[key] = path_trajectories(self.viewmats, frames, self.order, centres=centres)
        return self._paths[key]

    def path_partners(self, reach: float, frames: int = 21) -> dict[str, torch.Tensor]:
        """``warpgs.strategy.clearance.path_partners`` on this path: per input, the poses of the path next to it."""
        from warpgs.strategy.clearance import path_partners

        return path_partners(self.viewmats, self.names, self.order, reach, frames, trajectories=self.trajectories)

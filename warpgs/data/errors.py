"""The data layer's errors (``warpgs.data.scene`` re-exports them)."""


class SceneError(ValueError):
    """A scene could not be loaded; the message names the file and the problem."""


class DatasetNotFoundError(SceneError, FileNotFoundError):
    """A named dataset is not where warpgs looked; the message says where it looked and how to get it."""


__all__ = ["DatasetNotFoundError", "SceneError"]

"""Engine exceptions: every input problem becomes a SceneError with a located message."""


class EngineError(Exception):
    """Base class of engine errors."""


class SceneError(EngineError, ValueError):
    """The scene cannot be simulated as given (message says where and why)."""

"""Engine exceptions: every input problem becomes a SceneError with a located message."""


class EngineError(Exception):
    """Base class of engine errors."""


class SceneError(EngineError, ValueError):
    """The scene cannot be simulated as given (message says where and why)."""


class UnsupportedError(EngineError):
    """The request is valid but this version of the engine does not provide it."""


class CancelledError(EngineError):
    """The run was cancelled by its caller."""

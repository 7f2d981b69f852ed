"""User-facing errors of the layers above the config (the config's own is `schema.ConfigError`)."""


class PolicyError(ValueError):
    """A policy is unknown, unreadable, unsafe to load, or made for another scenario."""


class PolicyMismatchError(PolicyError):
    """A readable policy made for other spaces or another action mapping than the env's."""


class CheckpointError(OSError):
    """A checkpoint cannot be written or read; the message names the folder and the cause."""

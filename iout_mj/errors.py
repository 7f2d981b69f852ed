"""User-facing errors of the layers above the config (the config's own is `schema.ConfigError`).

Every error that bad input can cause derives from `IoutError`: the command line reports these
as "bad input" (exit 2) and lets any other exception show as the bug it is.
"""


class IoutError(Exception):
    """Bad input to iout-mj (a value, file or folder); the message says what is accepted."""


class UsageError(IoutError, ValueError):
    """An argument or a combination of arguments is invalid."""


class PolicyError(IoutError, ValueError):
    """A policy is unknown, unreadable, unsafe to load, or made for another scenario."""


class PolicyMismatchError(PolicyError):
    """A readable policy made for other spaces or another action mapping than the env's."""


class PolicyFormatError(PolicyError):
    """A policy folder is missing a file, damaged, unsafe to read, or not in this format."""


class CheckpointError(IoutError, OSError):
    """A checkpoint cannot be written or read; the message names the folder and the cause."""


class ResultFileError(IoutError, ValueError):
    """A file a command reads (evaluation results, traces, a benchmark run, a run's state) is
    missing, unreadable or malformed; the message names the file and what is wrong."""

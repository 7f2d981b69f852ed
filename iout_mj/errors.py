"""User-facing errors of the layers above the config (the config's own is `schema.ConfigError`).

Every error that bad input can cause derives from `IoutError`: the command line reports these
as "bad input" (exit 2) and lets any other exception show as the bug it is. The shared checks of
a count or a seed (`require_integer`, `require_seed`) raise them with what is accepted.
"""

import numbers


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


MAX_SEED = 2**32 - 1
"""The largest seed every RNG of the project takes (numpy's RandomState, the backends' task
RNG, and rliable's bootstrap through numpy's global RNG)."""


def require_integer(
    value: object, name: str, low: int, high: int, error: type[Exception] = UsageError
) -> int:
    """`value` as an int if it is an integer (not a bool) from `low` to `high`; else `error`
    saying what is accepted. One check for the counts a caller passes (N, K, episodes,
    candidates, substeps, bootstrap resamples)."""
    ok = not isinstance(value, bool) and isinstance(value, numbers.Integral)
    if not ok or not low <= value <= high:  # type: ignore[operator]
        raise error(f"{name}={value!r:.80} is invalid: accepted an integer from {low} to {high}")
    return int(value)  # type: ignore[call-overload]


def require_seed(
    value: object, name: str = "seed", allow_none: bool = False, error: type[Exception] = UsageError
) -> int | None:
    """A seed: an integer from 0 to `MAX_SEED`, or None where `allow_none` (fresh entropy)."""
    if value is None and allow_none:
        return None
    ok = not isinstance(value, bool) and isinstance(value, numbers.Integral)
    if not ok or not 0 <= value <= MAX_SEED:  # type: ignore[operator]
        also = " or None" if allow_none else ""
        raise error(
            f"{name}={value!r:.80} is invalid: accepted an integer from 0 to {MAX_SEED}{also}"
        )
    return int(value)  # type: ignore[call-overload]

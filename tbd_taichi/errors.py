"""Exceptions with messages that name the problem (never a Taichi traceback)."""


class TBDError(Exception):
    """Base class of every error this package raises on purpose."""


class InputError(TBDError, ValueError):
    """Bad input data: missing or unreadable file, wrong shape or dtype, NaN/inf, too few frames."""


class BackendError(TBDError, RuntimeError):
    """A Taichi backend that is unknown or not available on this machine."""


class ParameterError(TBDError, ValueError):
    """A parameter value outside its valid range."""


class WorkerError(TBDError, RuntimeError):
    """A helper process (the tracker's front-end process) failed, ended or stopped answering."""

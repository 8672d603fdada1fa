"""Errors raised by the numerics."""


class AnalysisError(ValueError):
    """A computation cannot be done on the data given; the message says why."""


class MetricUnavailable(AnalysisError):
    """A metric needs data the run does not have (e.g. torque it never reached)."""

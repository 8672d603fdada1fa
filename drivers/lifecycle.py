"""The ``with`` protocol of the devices and their simulators, written once.

A class mixes in the one that names its own methods: :class:`ClosedOnExit` for a device
that is open once constructed (``close()``), :class:`OpenedOnEnter` for one with ``open()``
and ``close()``, :class:`StartedOnEnter` for ``start()`` and ``close()``, and
:class:`RunsWhileEntered` for a simulator with ``start()`` and ``stop()``.
"""

from __future__ import annotations

from typing import Self


class ClosedOnExit:
    """``with device:`` gives the device and calls its ``close()`` at the end."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class OpenedOnEnter(ClosedOnExit):
    """``with device:`` calls its ``open()`` first."""

    def __enter__(self) -> Self:
        self.open()
        return self


class StartedOnEnter(ClosedOnExit):
    """``with device:`` calls its ``start()`` first."""

    def __enter__(self) -> Self:
        self.start()
        return self


class RunsWhileEntered:
    """``with simulator:`` calls its ``start()``, and its ``stop()`` at the end."""

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

"""A tap on the rows the engine records: every row still goes to the store (full rate, on
disk) and is also handed to the :class:`rig.web.live.LiveHub` for display.

:class:`TapStore` wraps a :class:`rig.store.Store` (the engine is given the wrapper);
``begin_run`` returns a :class:`TapRecorder` around the real
:class:`rig.store.RunRecorder`. Nothing of the engine is changed or mocked: the rows the page
draws are the rows written to ``samples.csv``.

Sample times: the engine stamps ``t_s`` from the monotonic time it takes right after
``begin_run`` returns, so ``t_wall_s = t0_wall + t_s`` with ``t0_wall`` the wall clock at that
return (error well under 1 ms); the page subtracts it from its own clock (same host) to get the
measured-to-drawn latency.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

from rig.store import RunRecorder, Store
from rig.web.live import LiveHub

ARCMIN_PER_DEG = 60.0


class TapRecorder:
    """A RunRecorder whose appended rows are also shown live (see the module docstring)."""

    def __init__(self, recorder: RunRecorder, hub: LiveHub) -> None:
        self._recorder = recorder
        self._hub = hub
        cols = recorder.columns
        self._i_t = cols.index("t_s")
        self._i_torque = cols.index("torque_Nm")
        self._i_angle = cols.index("output_angle_deg")
        self._i_temp = cols.index("temperature_C") if "temperature_C" in cols else None
        test = (getattr(recorder, "meta", None) or {}).get("test") or {}
        ratio = test.get("ratio")
        self._te: tuple[int, int, float] | None = None
        """A transmission error run: (input angle column, direction column, ratio); its rows
        also carry the output angle (deg), the raw TE (arcsec, docs/run-format.md before the
        mean) and the direction to the page."""
        if (test.get("kind") == "transmission_error" and isinstance(ratio, int | float)
                and ratio and "input_angle_deg" in cols and "direction" in cols):
            self._te = (cols.index("input_angle_deg"), cols.index("direction"), float(ratio))
        self._t0_wall = time.time()
        self.latest: tuple[float, ...] | None = None
        """The newest row: (t_s, torque_Nm, twist_arcmin, t_wall_s[, temperature_C])."""
        self.first: tuple[float, ...] | None = None
        """The run's first row, as :attr:`latest` (a run begins at zero torque)."""
        label = (getattr(recorder, "meta", None) or {}).get("label")
        hub.begin_run(recorder.run_id, label if isinstance(label, str) else None,
                      "transmission_error" if self._te is not None else None)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._recorder, name)

    def __enter__(self) -> TapRecorder:
        self._recorder.__enter__()
        return self

    def __exit__(self, *exc: Any) -> Any:
        return self._recorder.__exit__(*exc)

    def append(self, row: Sequence[float | str | None] | Mapping[str, float | str | None]
               ) -> None:
        """Append to the store, then hand (t_s, torque, twist, t_wall) to the hub."""
        self._recorder.append(row)
        if isinstance(row, Mapping):
            values = [row.get(c) for c in self._recorder.columns]
        else:
            values = list(row)
        t, torque, angle = values[self._i_t], values[self._i_torque], values[self._i_angle]
        if not all(isinstance(v, int | float) for v in (t, torque, angle)):
            return
        item = (float(t), float(torque), float(angle) * ARCMIN_PER_DEG,
                self._t0_wall + float(t))
        if math.isfinite(item[2]):
            temp = values[self._i_temp] if self._i_temp is not None else None
            self.latest = item if not isinstance(temp, int | float) else (*item, float(temp))
            if self.first is None:
                self.first = self.latest
            self._hub.add_rows([self._with_te(item, values)])

    def _with_te(self, item: tuple[float, ...], values: list[Any]) -> tuple[float, ...]:
        """``item`` plus (output angle deg, raw TE arcsec, direction) in a TE run."""
        if self._te is None:
            return item
        i_in, i_dir, ratio = self._te
        out_deg, in_deg, direction = values[self._i_angle], values[i_in], values[i_dir]
        if not all(isinstance(v, int | float) for v in (in_deg, direction)):
            return (*item, math.nan, math.nan, 0.0)
        te = 3600.0 * (float(out_deg) - float(in_deg) / ratio)
        return (*item, float(out_deg), te, float(direction))


class TapStore:
    """A Store whose new runs are tapped for the live display; everything else delegates."""

    def __init__(self, store: Store, hub: LiveHub) -> None:
        self._store = store
        self._hub = hub
        self.recorder: TapRecorder | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._store, name)

    def begin_run(self, meta: dict[str, Any], columns: list[str], **kwargs: Any) -> TapRecorder:
        recorder = TapRecorder(self._store.begin_run(meta, columns, **kwargs), self._hub)
        self.recorder = recorder
        return recorder

"""Measuring from a script: ``with rig.connect(simulated=True) as r: r.campaign(...)``.

The services of ``rig campaign run`` and ``rig measure`` do the work
(:func:`rig.measurement.service.run_campaign`, :func:`rig.measurement.single_run.measure_run`):
the same plan, engine, store and verdicts. A simulated rig is started (its own process) for
each campaign or run with that campaign's unit as its plant, as ``--simulated`` does; a real
rig (``rig=`` a rig TOML) is opened once for the whole ``with`` block.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from rig.api.data import Campaign, Run
from rig.core.errors import RigError, RunFormatError
from rig.core.json_files import finite_for_json
from rig.core.ranges import POSITION_DEG
from rig.engine.events import ProgressEvent
from rig.measurement.service import RigSession, open_session, plant_config_for, run_campaign
from rig.measurement.single_run import (
    MeasureRequest,
    measure_run,
    unit_data,
    with_simulated_plant,
)
from rig.plans import LoopParams
from rig.plans.campaign_file import CampaignFile, Limits, campaign_from_mapping, load_campaign
from rig.plans.estimate import check_duration, estimate
from rig.runformat import CAMPAIGN_JSON, read_campaign
from rig.runformat import Campaign as RawCampaign
from rig.store import Store, default_store_root
from simulators.plant.config import PlantConfig

__all__ = ["MEASURE_DEFAULTS", "Connection", "Progress", "connect", "read_stored_campaign"]

Progress = Callable[[ProgressEvent], None]
"""A progress callback: called with each :class:`rig.engine.events.ProgressEvent` (kind
"start", "step", "run_started", "run_finished", "fault", "finished" ...; step of n_steps,
elapsed_s and remaining_s in s, run_label, message, data) from the engine's thread."""

MEASURE_DEFAULTS: dict[str, Any] = {
    "rated_torque_Nm": 10.0, "amplitude_pct": 100.0, "mode": "equal_torque",
    "rate_Nm_per_s": 25.0, "steps_per_quarter": 4, "dwell_s": 0.05, "cycles": 1,
    "pre_cycles": 1, "zero_band_Nm": 0.3, "zero_rate_Nm_per_s": 0.3,
    "extra_levels_pct": [3.0],
}
"""The plan of :meth:`Connection.measure` unless given: the defaults of ``rig measure``."""


class Connection:
    """A rig opened for measuring from a script (use :func:`connect`).

    ``store``: the :class:`rig.store.Store` the runs go to.
    """

    def __init__(self, *, simulated: bool = False, rig: str | Path | None = None,
                 store: Store | str | Path | None = None,
                 samples: str | Path | None = None) -> None:
        if simulated == (rig is not None):
            raise RigError("say which rig: connect(simulated=True) starts the simulated rig, "
                           "connect(rig='rig.toml') opens a configured one; not both or neither")
        self.simulated = simulated
        self.rig = None if rig is None else Path(rig)
        self.store = store if isinstance(store, Store) else Store(
            default_store_root() if store is None else store, samples=samples)
        self._stack: contextlib.ExitStack | None = None
        self._session: RigSession | None = None

    def __enter__(self) -> Connection:
        self._stack = contextlib.ExitStack()
        if self.rig is not None:
            try:
                self._session = self._stack.enter_context(open_session(rig=self.rig))
            except BaseException:
                self._stack.close()
                raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the rig (a real rig's drivers; a simulated rig stops after each call)."""
        if self._stack is not None:
            self._stack.close()
        self._stack, self._session = None, None

    @contextlib.contextmanager
    def _open(self, plant: PlantConfig | None) -> Iterator[RigSession]:
        if self._stack is None:
            raise RigError("use the connection in a with block: with rig.connect(...) as r:")
        if self._session is not None:
            yield self._session
            return
        with open_session(simulated=True, plant=plant) as session:
            yield session

    def campaign(self, file_or_dict: str | Path | Mapping[str, Any] | CampaignFile, *,
                 progress: Progress | None = None, confirm_long: bool = False) -> Campaign:
        """Run a campaign (a TOML file, its mapping, or a validated CampaignFile; keys in
        docs/campaigns.md) into the store, as ``rig campaign run``. Returns the campaign read
        back from the store, its ``result`` the ``--json`` document (outcome, failures,
        per-run metrics). Bad input raises before anything moves (CampaignError naming the
        key), and so does a campaign expected to take longer than 8 h unless
        ``confirm_long`` (or the file's ``confirm_long = true``)."""
        if isinstance(file_or_dict, CampaignFile):
            camp = file_or_dict
        elif isinstance(file_or_dict, Mapping):
            camp = campaign_from_mapping(dict(file_or_dict))
        else:
            camp = load_campaign(file_or_dict)
        check_duration(estimate(camp.build_plan().steps()),
                       confirmed=confirm_long or camp.confirm_long,
                       how="confirm_long=True (or confirm_long = true in the file)")
        plant = plant_config_for(camp.unit_data(), camp.simulation, camp.source) \
            if self.simulated else None
        with self._open(plant) as session:
            result = finite_for_json(run_campaign(camp, session, self.store, progress=progress))
        return Campaign(read_stored_campaign(Path(result["path"])), result=result)

    def measure(self, unit: str | Path | Mapping[str, Any] | None = None, *,
                position_deg: float | None = None, limits: Mapping[str, Any] | None = None,
                profile: str = "nabtesco", operator: str | None = None,
                progress: Progress | None = None, confirm_long: bool = False,
                **plan: Any) -> Run:
        """Measure one hysteresis loop into the store, as ``rig measure``.

        ``unit``: the unit data (mapping or JSON file; simulated: also the plant's unit,
        default the default plant's); ``position_deg``: lock the input at this angle first;
        ``limits``: lost_motion_arcmin_max, backlash_arcmin_max, stiffness_Nm_per_arcmin_min;
        ``plan``: keys of the ``[plan]`` table (rated_torque_Nm, amplitude_pct, mode,
        steps_per_quarter, dwell_s ...; defaults :data:`MEASURE_DEFAULTS`). Returns the run
        read back from the store, its ``result`` the ``rig measure --json`` document. A
        value outside its range (:mod:`rig.core.ranges`), or a plan expected to take longer
        than 8 h without ``confirm_long``, raises before anything moves.
        """
        try:
            loop = LoopParams(**{**MEASURE_DEFAULTS, **plan})
            lim = Limits(**dict(limits or {}))
        except ValidationError as exc:
            raise RigError("; ".join(
                f"{'.'.join(str(p) for p in e['loc'])}: "
                f"{str(e['msg']).removeprefix('Value error, ')} (got {e.get('input')!r})"
                for e in exc.errors())) from None
        if position_deg is not None and (
                problem := POSITION_DEG.problem("position_deg", position_deg)):
            raise RigError(problem)
        request = MeasureRequest(loop=loop, position_deg=position_deg, unit=unit_data(unit),
                                 limits=lim, profile=profile, operator=operator)
        check_duration(estimate(request.plan().steps()), confirmed=confirm_long,
                       how="confirm_long=True")
        if self.simulated:
            request = with_simulated_plant(request)
        with self._open(request.plant) as session:
            measured = measure_run(request, session, self.store, progress=progress)
        result = finite_for_json(measured.result)
        return Run(self.store.load_run(result["run_id"]), result=result)

    def __repr__(self) -> str:
        what = "simulated rig" if self.simulated else f"rig {self.rig}"
        return f"<Connection to the {what}, store {self.store.location}>"


def read_stored_campaign(folder: Path) -> RawCampaign:
    """A campaign of the store; one that completed no run (campaign.json lists completed runs
    only) comes back with its meta and no runs."""
    try:
        return read_campaign(folder)
    except RunFormatError:
        import json

        meta = json.loads((folder / CAMPAIGN_JSON).read_text(encoding="utf-8"))
        if meta.get("runs"):
            raise
        return RawCampaign(meta=meta, runs=[], path=folder)


def connect(*, simulated: bool = False, rig: str | Path | None = None,
            store: Store | str | Path | None = None,
            samples: str | Path | None = None) -> Connection:
    """Open a rig for measuring from a script; use it in a ``with`` block.

    ``simulated=True`` starts the simulated rig (its own process) for each measurement;
    ``rig``: a rig configuration TOML (real or simulated device addresses). ``store``: a
    folder, a ``postgresql://`` URL (run files in ``samples``) or a Store; default
    ``$RIG_STORE`` else ``./rig-store``, as the CLI.
    """
    return Connection(simulated=simulated, rig=rig, store=store, samples=samples)

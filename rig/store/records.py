"""What the store's index says about a run or a campaign, and the calibration checks.

Sensor calibrations are given in a run's metadata as ``"calibration"``: a list of
``{"sensor": "<sensor id>", "due": "YYYY-MM-DD", ...}`` (more keys, such as a certificate
number, are kept). A calibration is *past due* at a run when its due date is earlier than
the UTC date on which the run started.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import date, datetime
from pathlib import Path
from typing import Any

from rig.store.backend import from_json

RUN_STATUSES = ("running", "completed", "aborted")
FINAL_STATUSES = ("completed", "aborted")


def parse_due(value: object) -> date:
    """A calibration due date from ISO text (``2027-01-31`` or a full ISO timestamp)."""
    if not isinstance(value, str):
        raise ValueError(f"due date must be an ISO date string, got {value!r}")
    try:
        return date.fromisoformat(value)
    except ValueError:
        pass
    try:
        return datetime.fromisoformat(value).date()
    except ValueError:
        raise ValueError(f"due date {value!r} is not an ISO date (YYYY-MM-DD)") from None


def check_calibration(calibration: object) -> list[dict[str, Any]]:
    """Validate a ``calibration`` list (see module doc); return it. ValueError names the entry."""
    if not isinstance(calibration, list):
        raise ValueError(
            f"meta['calibration'] must be a list of {{'sensor': id, 'due': 'YYYY-MM-DD'}}, "
            f"got {type(calibration).__name__}"
        )
    for i, entry in enumerate(calibration):
        where = f"meta['calibration'][{i}]"
        if not isinstance(entry, dict):
            raise ValueError(f"{where} must be an object, got {entry!r}")
        sensor = entry.get("sensor")
        if not isinstance(sensor, str) or not sensor:
            raise ValueError(f"{where}: 'sensor' must be a non-empty string, got {sensor!r}")
        try:
            parse_due(entry.get("due"))
        except ValueError as e:
            raise ValueError(f"{where} (sensor {sensor!r}): {e}") from None
    return calibration


def past_due(calibration: list[dict[str, Any]], started_at: str | None) -> list[str]:
    """One message per sensor whose calibration was past due when the run started."""
    if not calibration or not started_at:
        return []
    day = datetime.fromisoformat(started_at.replace("Z", "+00:00")).date()
    out = []
    for entry in calibration:
        try:
            due = parse_due(entry.get("due"))
        except ValueError:
            continue
        if due < day:
            out.append(
                f"calibration of sensor {entry.get('sensor')!r} was past due at the start of "
                f"the run (due {due.isoformat()}, run started {day.isoformat()})"
            )
    return out


@dataclass(frozen=True)
class RunInfo:
    """One row of the store's run index. Times are ISO 8601 UTC strings; ``path`` absolute.

    ``n_samples`` is known once the run has finished (None while running); ``metrics`` is
    the ``result`` dict given at finish (None if none). ``reason`` says why a run was aborted.
    ``outcome`` is run.json's ``outcome`` reduced to a word ("pass", "fail", ...; None if
    the run has none), indexed for the production history; ``design`` the unit's
    ``unit.design`` (else ``unit.model``), the design a production line makes.
    """

    run_id: str
    campaign_id: str | None
    unit_serial: str | None
    operator: str | None
    rig_id: str | None
    calibration: list[dict[str, Any]]
    software_version: str
    plan_name: str | None
    plan_version: str | None
    status: str
    reason: str | None
    started_at: str
    finished_at: str | None
    n_samples: int | None
    path: Path
    metrics: dict[str, Any] | None = None
    writer_pid: int | None = field(default=None, compare=False)
    writer_host: str | None = field(default=None, compare=False)
    outcome: str | None = None
    design: str | None = None
    label: str | None = field(default=None, compare=False)
    """The plan's name of the run (run.json ``label``: ``pos090-a100-r0``), when the index
    keeps the run's record; the page names a run by it beside its id."""

    @property
    def calibration_warnings(self) -> list[str]:
        """Sensors whose calibration was past due when this run started (empty if none)."""
        return past_due(self.calibration, self.started_at)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field, plus ``calibration_warnings``."""
        return _json_ready(self, RUN_DICT_KEYS)


RUN_DICT_KEYS = (  # the keys of RunInfo.to_dict, in order
    "run_id", "campaign_id", "status", "reason", "unit_serial", "operator", "rig_id",
    "plan_name", "plan_version", "software_version", "started_at", "finished_at",
    "n_samples", "path", "calibration", "calibration_warnings", "metrics", "writer_pid",
    "writer_host", "outcome", "design",
)


@dataclass(frozen=True)
class CampaignInfo:
    """One row of the store's campaign index (times ISO 8601 UTC; ``path`` absolute)."""

    campaign_id: str
    name: str
    status: str
    started_at: str
    finished_at: str | None
    path: Path
    meta: dict[str, Any]
    summary: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field."""
        return _json_ready(self, _CAMPAIGN_DICT_KEYS)


_CAMPAIGN_DICT_KEYS = (
    "campaign_id", "name", "status", "started_at", "finished_at", "path", "meta", "summary",
)


def _json_ready(record: RunInfo | CampaignInfo, keys: tuple[str, ...]) -> dict[str, Any]:
    """``record``'s attributes ``keys`` in that order, its path as text."""
    out = {key: getattr(record, key) for key in keys}
    out["path"] = str(record.path)
    return out


def run_info(row: Mapping[str, Any], root: Path) -> RunInfo:
    """A :class:`RunInfo` from a ``runs`` row; ``path`` made absolute under ``root``."""
    return RunInfo(
        **{key: row[key] for key in _RUN_PLAIN_COLUMNS},
        calibration=from_json(row["calibration"]),
        path=root / row["path"],
        metrics=from_json(row["metrics"]),
        outcome=_indexed_outcome(row),
        design=row.get("design"),
        label=_indexed_label(row),
    )


def _indexed_label(row: Mapping[str, Any]) -> str | None:
    meta = from_json(row.get("meta"))
    label = meta.get("label") if isinstance(meta, dict) else None
    return label if isinstance(label, str) else None


# The columns a RunInfo takes as they are.
_RUN_PLAIN_COLUMNS = (
    "run_id", "campaign_id", "unit_serial", "operator", "rig_id", "software_version",
    "plan_name", "plan_version", "status", "reason", "started_at", "finished_at",
    "n_samples", "writer_pid", "writer_host",
)


def _indexed_outcome(row: Mapping[str, Any]) -> str | None:
    """The run's outcome as every view shows it (rig/results/outcome.py ``recorded_outcome``) when
    the row keeps the run's record (``meta``); else the indexed word as it is."""
    from rig.results.outcome import recorded_outcome

    meta = from_json(row.get("meta"))
    if not isinstance(meta, dict):
        return row.get("outcome")
    metrics = from_json(row.get("metrics"))
    return recorded_outcome({**meta, "status": row["status"], "outcome": row.get("outcome"),
                             "result": metrics if metrics is not None else meta.get("result")})


def campaign_info(row: Mapping[str, Any], root: Path) -> CampaignInfo:
    """A :class:`CampaignInfo` from a ``campaigns`` row."""
    return CampaignInfo(
        **{key: row[key] for key in ("campaign_id", "name", "status", "started_at",
                                     "finished_at")},
        path=root / row["path"],
        meta=from_json(row["meta"]),
        summary=from_json(row["summary"]),
    )

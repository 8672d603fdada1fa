"""The Python API of backlash-rig (``import rig``; docs/python-api.md).

- :func:`open`: a run or campaign from a path or a store id; samples as Arrow/pandas with
  the twist as a column, ``results()`` one tidy row per run, ``plot()``.
- :func:`analyse`, :func:`diagnose`, :func:`model`: the reports of ``rig analyse``,
  ``rig diagnose``, ``rig model`` (``to_dict()`` is their ``--json``).
- :class:`Store` (``Store(url).runs(...)`` a DataFrame) and :func:`connect` (measuring).
"""

from __future__ import annotations

from pathlib import Path

from rig.api.connect import Connection, connect, read_stored_campaign
from rig.api.data import TWIST_COLUMN, Campaign, Run
from rig.api.reports import Analysis, Diagnosis, Model, analyse, diagnose, model
from rig.core.errors import RigError
from rig.runformat import is_campaign, read_campaign, read_run
from rig.store import Store, UnknownIdError, default_store_root, is_database_url

__all__ = [
    "TWIST_COLUMN", "Analysis", "Campaign", "Connection", "Diagnosis", "Model", "Run", "Store",
    "analyse", "connect", "diagnose", "model", "open",
]


def open(path_or_store_id: str | Path, store: Store | str | Path | None = None,  # noqa: A001
         ) -> Run | Campaign:
    """A run or a campaign: from a path (run folder, run.json, bare CSV or Parquet samples,
    campaign folder or campaign.json), else by its id in ``store`` (a Store, a folder or a
    ``postgresql://`` URL; default ``$RIG_STORE`` else ``./rig-store``, as the CLI).

    A path that exists is always read as a path; ``store`` given means an id of that store.
    """
    if store is None and Path(path_or_store_id).exists():
        if is_campaign(path_or_store_id):
            return Campaign(read_campaign(path_or_store_id))
        return Run(read_run(path_or_store_id))
    name = str(path_or_store_id)
    if store is None:
        store = default_store_root()
        if not is_database_url(store) and not Path(store).exists():
            raise RigError(f"{name}: no such file or folder, and no store at {store} to look "
                           "it up in (give store=...)")
    st = store if isinstance(store, Store) else Store(store, create=False)
    try:
        return Run(st.load_run(st.get_run(name).run_id))
    except UnknownIdError:
        pass
    try:
        info = st.get_campaign(name)
    except UnknownIdError:
        raise UnknownIdError(f"no run or campaign {name!r} in the store {st.location}") from None
    return Campaign(read_stored_campaign(info.path))

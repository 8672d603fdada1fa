"""Re-analysis of stored runs at scale (``rig reanalyse``), on a Dask cluster.

After a model or software update, every completed run is analysed again (the ``rig analyse
--json`` object, :func:`rig.results.analyse.analyse_run`) and every completed campaign diagnosed
again
(:func:`rig.results.diagnose.diagnose_path`). The results are written back to the store's
``results`` table with the software version that produced them; earlier results (of other
versions) are kept. A run or campaign that already has a result of this version is skipped,
so an interrupted re-analysis resumes where it stopped.

The work runs on Dask (``dask.distributed``): a local cluster of ``workers`` processes by
default, or the scheduler at ``dask_address`` (``tcp://host:8786``), whose workers must
reach the sample files at the same path. Each task runs with one BLAS thread (rig/core/blas.py),
so N workers use N cores. Workers only read files; the client writes
the results into the store as they arrive.

A run whose files are missing or unreadable is reported by its run id (and not written, so
it is retried next time); an analysis that fails on readable data is stored as an error
result (the same software would fail again).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rig import __version__
from rig.core.json_files import json_safe
from rig.store import Store

BATCH = 16  # jobs per Dask task: keeps the scheduler's per-task overhead small


@dataclass(frozen=True)
class Job:
    """One run to analyse or one campaign to diagnose: kind "run"/"campaign", id, folder,
    and the lost-motion profile (None: the run.json ``profile``, else the default)."""

    kind: str
    target_id: str
    path: str
    profile: str | None = None


@dataclass
class Summary:
    """What a re-analysis did (``rig reanalyse`` prints it)."""

    software_version: str
    n_runs: int = 0
    n_campaigns: int = 0
    skipped: int = 0
    written: int = 0
    errors: int = 0
    unreadable: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def run_job(job: Job) -> dict[str, Any]:
    """Do one job (on a worker): ``{"job", "status": ok|error|unreadable, "metrics" or
    "diagnosis", "error"}``."""
    from analysis.errors import AnalysisError
    from rig.core.errors import RigError
    from rig.runformat import read_run, read_run_or_campaign

    out: dict[str, Any] = {"job": job, "status": "ok", "metrics": None, "diagnosis": None,
                           "error": None}
    try:
        data = (read_run(Path(job.path), allow_truncated_tail=True) if job.kind == "run"
                else read_run_or_campaign(job.path))
    except (RigError, OSError, ValueError) as exc:
        out.update(status="unreadable", error=f"{job.kind} {job.target_id}: {exc}")
        return out
    try:
        if job.kind == "run":
            from rig.results.any_run import analyse_any_run, result_record

            profile = job.profile or data.meta.get("profile")
            out["metrics"] = json_safe(result_record(analyse_any_run(data, profile=profile)))
        else:
            from rig.results.diagnose import diagnose_campaign, report_dict

            out["diagnosis"] = json_safe(report_dict(data, diagnose_campaign(data)))
    except (AnalysisError, RigError, ValueError) as exc:
        out.update(status="error", error=f"{type(exc).__name__}: {exc}")
    return out


def run_batch(jobs: list[Job]) -> list[dict[str, Any]]:
    """A Dask task: several jobs in a row, with one BLAS thread (rig/core/blas.py: a worker of a
    remote cluster may have started with a thread per core; one task per worker thread then
    uses one core)."""
    from rig.core.blas import limit_blas_threads

    with limit_blas_threads():
        return [run_job(j) for j in jobs]


def plan(store: Store, *, since: str | None = None,
         software_version: str = __version__) -> tuple[list[Job], Summary]:
    """The jobs still to do (completed runs and campaigns started at or after ``since``
    without a result of ``software_version``) and the summary so far."""
    summary = Summary(software_version)
    done = {r["run_id"] or r["campaign_id"]
            for r in store.results(software_version=software_version)}
    jobs: list[Job] = []
    for info in store.list_runs(status="completed", since=since)[::-1]:
        summary.n_runs += 1
        if info.run_id in done:
            summary.skipped += 1
            continue
        jobs.append(Job("run", info.run_id, str(info.path)))
    since_iso = _since_text(since)
    for camp in store.list_campaigns()[::-1]:
        if camp.status != "completed" or (since_iso and camp.started_at < since_iso):
            continue
        summary.n_campaigns += 1
        if camp.campaign_id in done:
            summary.skipped += 1
            continue
        jobs.append(Job("campaign", camp.campaign_id, str(camp.path)))
    return jobs, summary


def _since_text(since: str | None) -> str | None:
    from rig.store import _iso_bound

    return _iso_bound(since, "since")


def _client(dask_address: str | None, workers: int | None):
    from dask.distributed import Client, LocalCluster

    if dask_address:
        return Client(dask_address, timeout="10s")
    import dask

    from rig.core.blas import ONE_THREAD_ENV

    # the workers' BLAS start with one thread: set before the worker process starts (a
    # Nanny's ``env`` comes after numpy has loaded there, too late for its OpenBLAS)
    key = "distributed.nanny.pre-spawn-environ"
    with dask.config.set({key: {**dask.config.get(key, {}), **ONE_THREAD_ENV}}):
        cluster = LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=40)
    return Client(cluster)


def reanalyse(
    store: Store,
    *,
    since: str | None = None,
    dask_address: str | None = None,
    workers: int | None = None,
    software_version: str = __version__,
    on_progress: Callable[[int, int], None] | None = None,
    batch: int = BATCH,
) -> Summary:
    """Re-analyse (module doc). ``on_progress(done, total)`` after each finished job."""
    from dask.distributed import as_completed

    jobs, summary = plan(store, since=since, software_version=software_version)
    total = len(jobs)
    if on_progress is not None:
        on_progress(0, total)
    if not jobs:
        return summary
    client = _client(dask_address, workers)
    try:
        futures = client.map(run_batch, list(_chunks(jobs, batch)), pure=False)
        finished = 0
        for future in as_completed(futures):
            for result in future.result():
                _write(store, result, summary, software_version)
                finished += 1
                if on_progress is not None:
                    on_progress(finished, total)
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None:
            cluster.close()
    return summary


def _chunks(jobs: list[Job], size: int) -> Iterator[list[Job]]:
    for i in range(0, len(jobs), size):
        yield jobs[i:i + size]


def _write(store: Store, result: dict[str, Any], summary: Summary, version: str) -> None:
    job: Job = result["job"]
    if result["status"] == "unreadable":
        summary.unreadable.append(result["error"])
        return
    key = {"run_id": job.target_id} if job.kind == "run" else {"campaign_id": job.target_id}
    if store.add_result(software_version=version, metrics=result["metrics"],
                        diagnosis=result["diagnosis"], error=result["error"], **key):
        summary.written += 1
    if result["status"] == "error":
        summary.errors += 1

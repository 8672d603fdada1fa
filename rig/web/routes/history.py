"""History from the store: runs, campaigns, a run's loop for drawing, downloads, diagnosis.

Everything here only reads (no token needed). Run and campaign ids are checked against the
store's id pattern (no dots, no slashes) before the store resolves them through its index,
so no request can name a file outside the store.
"""

from __future__ import annotations

import contextlib
import json
import tempfile
import zipfile
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response

from rig.core.errors import RigError
from rig.core.json_files import json_safe
from rig.core.redact import without_paths
from rig.results.outcome import (
    OUTCOME_MEANINGS,
    OUTCOME_WORDS,
    OUTCOMES,
    outcome_word,
    recorded_campaign_outcome,
    recorded_outcome,
)
from rig.runformat import RUN_JSON, SAMPLES_CSV, sample_columns, samples_csv_bytes
from rig.store import Store, UnknownIdError
from rig.store.records import CampaignInfo, RunInfo
from rig.web.live import decimate
from rig.web.models import (
    ID_PATTERN,
    CampaignSummary,
    ErrorBody,
    LoopData,
    OutcomeWord,
    RunDetail,
    RunSummary,
    TEData,
)

router = APIRouter(prefix="/api", tags=["history"])

RunId = Annotated[str, PathParam(pattern=ID_PATTERN, description="A run id of the store.")]
CampaignId = Annotated[str, PathParam(pattern=ID_PATTERN,
                                      description="A campaign id of the store.")]
ERROR_JSON = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}}
NOT_FOUND: dict[int | str, dict[str, Any]] = {
    404: {"model": ErrorBody, "content": ERROR_JSON, "description": "No such run or campaign."}}
UNPROCESSABLE: dict[int | str, dict[str, Any]] = {
    409: {"model": ErrorBody, "content": ERROR_JSON,
          "description": "The data cannot be processed (the message says why)."}}


def _store(request: Request) -> Store:
    return request.app.state.store


def summary_of(info: RunInfo) -> dict[str, Any]:
    d = info.to_dict()
    d["verdict"] = None if info.outcome is None else outcome_word(info.outcome)
    d["label"] = info.label
    keys = RunSummary.model_fields
    return json_safe({k: d.get(k) for k in keys})


@router.get("/outcomes", response_model=dict[str, OutcomeWord],
            summary="The verdict vocabulary: outcome code -> displayed word and meaning")
def outcomes() -> dict[str, dict[str, str]]:
    """The one mapping the page shows verdicts with (rig/results/outcome.py)."""
    return {code: {"word": OUTCOME_WORDS[code], "meaning": OUTCOME_MEANINGS[code]}
            for code in OUTCOMES}


def _run_info(store: Store, run_id: str) -> RunInfo:
    try:
        return store.get_run(run_id)
    except UnknownIdError as exc:
        raise HTTPException(404, str(exc)) from exc


@router.get("/runs", response_model=list[RunSummary], summary="Runs of the store, newest first")
def list_runs(request: Request,
              status: Annotated[str | None, Query(pattern="^(running|completed|aborted)$")]
              = None,
              campaign_id: Annotated[str | None, Query(pattern=ID_PATTERN)] = None,
              limit: Annotated[int, Query(ge=1, le=1000)] = 200) -> list[dict[str, Any]]:
    runs = _store(request).list_runs(campaign_id=campaign_id, status=status, limit=limit)
    return [summary_of(r) for r in runs]


@router.get("/runs/{run_id}", response_model=RunDetail, responses={**NOT_FOUND, **UNPROCESSABLE},
            summary="One run: its run.json and index row")
def get_run(request: Request, run_id: RunId) -> dict[str, Any]:
    info = _run_info(_store(request), run_id)
    meta = _read_json(info.path / RUN_JSON)
    return {"summary": summary_of(info), "meta": json_safe(meta),
            "columns": sample_columns(info.path)}


@router.get("/runs/{run_id}/loop", response_model=LoopData,
            responses={**NOT_FOUND, **UNPROCESSABLE},
            summary="A run's loop (torque, twist, model loop) for drawing, decimated")
def run_loop(request: Request, run_id: RunId,
             max_points: Annotated[int, Query(ge=10, le=100_000)] = 5000) -> dict[str, Any]:
    from rig.results.analyse import analyse_run, loop_centre_arcmin

    run = _stored_run(request, run_id)
    torque = run.torque_Nm
    twist = run.output_angle_deg * 60.0
    model = None
    metrics: dict[str, Any] = {}
    error = None
    band = None
    try:
        analysis = analyse_run(run, profile=run.meta.get("profile"))
        twist = analysis.twist_arcmin
        model_twist = analysis.model_twist_arcmin()
        metrics = json_safe(analysis.to_dict())
        recorded = run.meta.get("result") if isinstance(run.meta.get("result"), dict) else {}
        if recorded.get("crosscheck_max_diff_Nm") is not None:
            metrics["crosscheck_max_diff_Nm"] = recorded["crosscheck_max_diff_Nm"]
        band = analysis.lost_motion_pct / 100.0 * analysis.rated_torque_Nm
    except Exception as exc:  # an aborted or short run still has a loop to draw
        model_twist = None
        error = without_paths(f"{type(exc).__name__}: {exc}", store_roots(_store(request)))
    outcome = recorded_outcome(run.meta)
    n = int(run.n_samples)
    keep = decimate(list(range(n)), max_points) if n else []
    centre = loop_centre_arcmin(twist) if n else 0.0
    if model_twist is not None:
        model = [float(model_twist[i]) - centre for i in keep]
    return json_safe({
        "run_id": run_id, "n_samples": n,
        "torque_Nm": [float(torque[i]) for i in keep],
        "twist_arcmin": [float(twist[i]) - centre for i in keep],
        "model_twist_arcmin": model, "band_Nm": band, "metrics": metrics,
        "analysis_error": error, "outcome": outcome,
        "verdict": None if outcome is None else outcome_word(outcome),
        "limits": run.meta.get("limits"), "status": run.meta.get("status"),
    })


@router.get("/runs/{run_id}/te", response_model=TEData,
            responses={**NOT_FOUND, **UNPROCESSABLE},
            summary="A transmission error run's TE against the output angle, for drawing "
                    "(409 for a run of another test)")
def run_te(request: Request, run_id: RunId,
           max_points: Annotated[int, Query(ge=10, le=100_000)] = 5000) -> dict[str, Any]:
    """What the page draws of a stored TE run (History): never a loop (issue 33 item 15)."""
    import numpy as np

    from rig.plans import TE_KIND
    from rig.results.te_curve import te_arcsec

    run = _stored_run(request, run_id)
    ratio = run.test.get("ratio")
    if run.test.get("kind") != TE_KIND:
        raise HTTPException(409, f"run {run_id} is not a transmission error run: its loop "
                                 f"is GET /api/runs/{run_id}/loop")
    inp = run.input_angle_deg
    if (inp is None or "direction" not in run.data or not isinstance(ratio, int | float)
            or not ratio):
        raise HTTPException(409, f"run {run_id} has no input angle, direction or ratio: no "
                                 f"transmission error to draw")
    direction = run.data["direction"]
    if not isinstance(direction, np.ndarray):
        raise HTTPException(409, f"run {run_id}: its direction column is not numeric")
    out = run.output_angle_deg
    te = te_arcsec(out, inp, float(ratio))
    turning = [i for i in range(run.n_samples) if direction[i] in (1.0, -1.0)]
    keep = decimate(turning, max_points)
    outcome = recorded_outcome(run.meta)
    result = run.meta.get("result") if isinstance(run.meta.get("result"), dict) else {}
    return json_safe({
        "run_id": run_id, "n_samples": int(run.n_samples),
        "output_deg": [float(out[i]) for i in keep], "te_arcsec": [float(te[i]) for i in keep],
        "direction": [float(direction[i]) for i in keep], "result": result,
        "outcome": outcome, "verdict": None if outcome is None else outcome_word(outcome),
        "limits": run.meta.get("limits"), "status": run.meta.get("status"),
    })


@router.get("/runs/{run_id}/samples.csv", response_class=FileResponse, responses={
    **NOT_FOUND, 200: {"content": {"text/csv": {}}, "description": "samples.csv"}},
    summary="Download a run's samples (CSV)")
def run_csv(request: Request, run_id: RunId) -> Response:
    store = _store(request)
    info = _run_info(store, run_id)
    if (info.path / SAMPLES_CSV).is_file():  # a run being recorded: its CSV stream
        return FileResponse(info.path / SAMPLES_CSV, media_type="text/csv",
                            filename=f"{run_id}.csv")
    return Response(_samples_csv(store, run_id), media_type="text/csv", headers={
        "Content-Disposition": f'attachment; filename="{run_id}.csv"'})


@router.get("/runs/{run_id}/run.zip", response_class=Response, responses={
    **NOT_FOUND, 200: {"content": {"application/zip": {}},
                       "description": "The run folder in rig-run/1 (run.json + samples.csv)"}},
    summary="Download a run as a rig-run/1 zip")
def run_zip(request: Request, run_id: RunId) -> Response:
    store = _store(request)
    info = _run_info(store, run_id)
    with tempfile.TemporaryFile() as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            if (info.path / RUN_JSON).is_file():
                zf.write(info.path / RUN_JSON, f"{run_id}/{RUN_JSON}")
            if (info.path / SAMPLES_CSV).is_file():
                zf.write(info.path / SAMPLES_CSV, f"{run_id}/{SAMPLES_CSV}")
            else:  # a stored run keeps Parquet; the exchange format is CSV
                zf.writestr(f"{run_id}/{SAMPLES_CSV}", _samples_csv(store, run_id))
        tmp.seek(0)
        data = tmp.read()
    return Response(data, media_type="application/zip", headers={
        "Content-Disposition": f'attachment; filename="{run_id}.zip"'})


def _stored_run(request: Request, run_id: str) -> Any:
    """The stored run ``run_id`` read whole (404 if the store has none, 409 if its files
    cannot be read)."""
    store = _store(request)
    _run_info(store, run_id)
    try:
        return store.load_run(run_id)
    except RigError as exc:
        raise HTTPException(409, f"run {run_id} cannot be read: {exc}") from exc


def _samples_csv(store: Store, run_id: str) -> bytes:
    """A stored run's samples as rig-run/1 CSV (409 if its files cannot be read)."""
    try:
        return samples_csv_bytes(store.load_run(run_id))
    except RigError as exc:
        raise HTTPException(409, f"run {run_id} cannot be read: {exc}") from exc


@router.get("/runs/{run_id}/loop.png", response_class=Response, responses={
    **NOT_FOUND, **UNPROCESSABLE, 200: {"content": {"image/png": {}},
                                        "description": "The loop with the model (PNG)"}},
    summary="Download the PNG of a run's loop")
def run_png(request: Request, run_id: RunId) -> Response:
    from rig.reports.loop_plots import plot_loops
    from rig.results.analyse import analyse_run

    store = _store(request)
    _run_info(store, run_id)
    try:
        run = store.load_run(run_id)
        analysis = analyse_run(run, profile=run.meta.get("profile"))
    except Exception as exc:  # not analysable: no figure
        raise HTTPException(409, f"run {run_id} has no loop to plot: {exc}") from exc
    with tempfile.TemporaryDirectory() as tmp:
        path = plot_loops([analysis], Path(tmp) / "loop.png")
        data = path.read_bytes()
    return Response(data, media_type="image/png", headers={
        "Content-Disposition": f'attachment; filename="{run_id}-loop.png"'})


@router.get("/campaigns", response_model=list[CampaignSummary],
            summary="Campaigns of the store, newest first")
def list_campaigns(request: Request) -> list[dict[str, Any]]:
    store = _store(request)
    return [_campaign(store, c.campaign_id) for c in store.list_campaigns()]


def _campaign(store: Store, campaign_id: str) -> dict[str, Any]:
    try:
        info = store.get_campaign(campaign_id)
    except UnknownIdError as exc:
        raise HTTPException(404, str(exc)) from exc
    runs = store.list_runs(campaign_id=campaign_id)
    d = info.to_dict()
    d["no_diagnosis"] = no_diagnosis(store, info, runs)
    summary = info.summary or {}
    d["outcome"] = recorded_campaign_outcome(
        info.meta.get("outcome") or summary.get("outcome"),
        info.meta.get("limits") or summary.get("limits"), [r.outcome for r in runs],
        info.status)
    d["verdict"] = None if d["outcome"] is None else outcome_word(d["outcome"])
    return json_safe({k: d.get(k) for k in CampaignSummary.model_fields if k != "runs"}
                     | {"runs": [summary_of(r) for r in runs]})


@router.get("/campaigns/{campaign_id}", response_model=CampaignSummary, responses=NOT_FOUND,
            summary="One campaign: results (lost motion against position, pass/fail) and runs")
def get_campaign(request: Request, campaign_id: CampaignId) -> dict[str, Any]:
    return _campaign(_store(request), campaign_id)


def _diagnosis_folder(store: Store) -> Path:
    return store.root / "web" / "diagnosis"


def no_diagnosis(store: Store, info: CampaignInfo, runs: list[RunInfo]) -> str | None:
    """Why a campaign has no diagnosis report, as one plain sentence for the operator; None
    when it has one or can have one (made when first asked for). The diagnosis reads the
    campaign's completed runs: a campaign aborted before any was completed has none, and a
    diagnosis tried once and refused keeps its reason (``<id>.none`` beside the cache)."""
    if info.status == "running":
        return "no diagnosis yet: the campaign is still running"
    if any(r.status == "completed" for r in runs):
        refused = _diagnosis_folder(store) / f"{info.campaign_id}.none"
        with contextlib.suppress(OSError):
            if refused.is_file():
                return refused.read_text(encoding="utf-8").strip() or None
        return None
    summary = info.summary or {}
    reason = summary.get("reason") or info.meta.get("reason") or next(
        (r.reason for r in reversed(runs) if r.reason), None)
    why = f" ({without_paths(str(reason), store_roots(store))})" if reason else ""
    if info.status != "aborted":
        return f"no diagnosis: no run of the campaign was completed{why}"
    where = ("before its first run" if not runs else "in its first run" if len(runs) == 1
             else f"before any of its {len(runs)} runs was completed")
    return f"no diagnosis: the campaign was aborted {where}{why}"


def store_roots(store: Store) -> list[str]:
    """The store's folder as given and as resolved: what an error never shows."""
    roots = [str(store.root)]
    with contextlib.suppress(OSError, RuntimeError):
        roots.append(str(store.root.resolve()))
    return roots


def _diagnosis(store: Store, campaign_id: str, suffix: str) -> str:
    """The campaign's diagnosis as ``suffix`` ("json" or "html"), computed once and cached
    beside the store (``<store>/web/diagnosis/``). A campaign without one is a 409 whose
    detail says why in one sentence, never with a folder of the server."""
    from rig.web.report import diagnose_campaign_folder
    from rig.web.workers import PoolBusy, run_in_worker

    try:
        info = store.get_campaign(campaign_id)
    except UnknownIdError as exc:
        raise HTTPException(404, str(exc)) from exc
    if info.status == "running":
        raise HTTPException(409, f"campaign {campaign_id} is still running: no diagnosis yet")
    folder = _diagnosis_folder(store)
    cache = folder / f"{campaign_id}.{suffix}"
    if not cache.is_file():
        why = no_diagnosis(store, info, store.list_runs(campaign_id=campaign_id))
        if why is not None:
            raise HTTPException(409, f"campaign {campaign_id} has {why}")
        try:
            report, page = run_in_worker(diagnose_campaign_folder, info.path)
        except Exception as exc:  # too few runs, unreadable runs: said, not a 500
            text = without_paths(str(exc), store_roots(store)).removeprefix(
                f"campaign {campaign_id}: ")
            if isinstance(exc, RigError) and not isinstance(exc, PoolBusy) and (
                    "worker was stopped" not in text):  # the data's answer: kept
                with contextlib.suppress(OSError):
                    folder.mkdir(parents=True, exist_ok=True)
                    (folder / f"{campaign_id}.none").write_text(
                        f"no diagnosis: {text}", encoding="utf-8")
            raise HTTPException(409, f"campaign {campaign_id} cannot be diagnosed: "
                                     f"{text}") from exc
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{campaign_id}.json").write_text(json.dumps(report, indent=2),
                                                    encoding="utf-8")
        (folder / f"{campaign_id}.html").write_text(page, encoding="utf-8")
    return cache.read_text(encoding="utf-8")


@router.get("/campaigns/{campaign_id}/diagnosis.json",
            responses={**NOT_FOUND, **UNPROCESSABLE,
                       200: {"content": {"application/json": {}},
                             "description": "The rig-diagnosis/1 report"}},
            summary="The diagnosis report of a campaign (rig-diagnosis/1 JSON)")
def campaign_diagnosis(request: Request, campaign_id: CampaignId) -> JSONResponse:
    return JSONResponse(json.loads(_diagnosis(_store(request), campaign_id, "json")))


@router.get("/campaigns/{campaign_id}/diagnosis.html", response_class=HTMLResponse,
            responses={**NOT_FOUND, **UNPROCESSABLE},
            summary="The diagnosis report of a campaign as an HTML page")
def campaign_diagnosis_html(request: Request, campaign_id: CampaignId) -> HTMLResponse:
    return HTMLResponse(_diagnosis(_store(request), campaign_id, "html"))


CertFormat = Annotated[Literal["pdf", "html"], PathParam(
    description="pdf (one A4 page, a download) or html (self-contained page)")]
CERTIFICATE = {**NOT_FOUND, **UNPROCESSABLE, 200: {
    "content": {"application/pdf": {}, "text/html": {}},
    "description": "The unit's test certificate (rig certificate)"}}


def _certificate(store: Store, kind: str, ident: str, fmt: str) -> Response:
    """The certificate of a finished run or campaign, drawn in the analysis worker."""
    from rig.reports.certificate import certificate_bytes
    from rig.web.workers import run_in_worker

    try:
        info = store.get_run(ident) if kind == "run" else store.get_campaign(ident)
    except UnknownIdError as exc:
        raise HTTPException(404, str(exc)) from exc
    if info.status == "running":
        raise HTTPException(409, f"{kind} {ident} is still running")
    try:
        data = run_in_worker(certificate_bytes, str(info.path), store.url or str(store.root),
                             str(store.root) if store.url else None, fmt)
    except Exception as exc:  # unreadable record, no PDF engine: said, not a 500
        raise HTTPException(409, f"{kind} {ident} has no certificate: {exc}") from exc
    if fmt == "html":
        return HTMLResponse(data.decode("utf-8"))
    return Response(data, media_type="application/pdf", headers={
        "Content-Disposition": f'attachment; filename="{ident}-certificate.pdf"'})


@router.get("/runs/{run_id}/certificate.{fmt}", response_class=Response, responses=CERTIFICATE,
            summary="The test certificate of a run (PDF or HTML)")
def run_certificate(request: Request, run_id: RunId, fmt: CertFormat) -> Response:
    return _certificate(_store(request), "run", run_id, fmt)


@router.get("/campaigns/{campaign_id}/certificate.{fmt}", response_class=Response,
            responses=CERTIFICATE, summary="The test certificate of a campaign (PDF or HTML)")
def campaign_certificate(request: Request, campaign_id: CampaignId, fmt: CertFormat
                         ) -> Response:
    return _certificate(_store(request), "campaign", campaign_id, fmt)


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise HTTPException(409, f"{path.name} of this run cannot be read: {exc}") from exc
    return data if isinstance(data, dict) else {}

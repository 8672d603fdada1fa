"""Commands: status, plan preview, start/pause/resume/abort, E-stop, tare, input lock.

Everything that moves the rig or changes data needs the operator token
(:func:`rig.web.auth.require_operator`); the E-stop does not: it only ever takes the rig to
its safe state, and a stop must never wait for a login.
"""

from __future__ import annotations

import asyncio
import json
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Request
from fastapi import Path as PathParam
from fastapi.responses import JSONResponse

from rig.core.errors import RigError
from rig.plans.campaign_file import CampaignError
from rig.web import campaign_files
from rig.web.auth import Operator, is_operator
from rig.web.controller import ControlError, RigController, compute_preview, start_identity_problem
from rig.web.models import (
    NAME_PATTERN,
    UNIT_MODELS,
    CampaignFileName,
    CampaignSetup,
    CampaignUpload,
    ErrorBody,
    InputLockAnswer,
    InputLockRequest,
    Message,
    PlanPreview,
    ResetFaultsRequest,
    ResetFaultsResult,
    RunRequest,
    Status,
    TareResult,
    UnitExample,
)
from rig.web.workers import PoolBusy, pool_full, run_in_worker

router = APIRouter(prefix="/api", tags=["control"])

AUTH = {401: {"model": ErrorBody, "description": "No operator token: the page can only watch."},
        403: {"model": ErrorBody, "description": "Wrong operator token."}}
CONFLICT = {409: {"model": ErrorBody, "description": "Not possible now (the message says why)."}}
BAD_BODY = {400: {"model": ErrorBody, "description": "The body could not be parsed (not UTF-8 "
                                                     "JSON)."}}


def _controller(request: Request) -> RigController:
    return request.app.state.controller


def _do(action: Any) -> Any:
    try:
        return action()
    except ControlError as exc:
        raise HTTPException(409, str(exc)) from exc


@router.get("/status", response_model=Status, summary="The rig now: devices, live values, "
            "progress, fault, results")
def status(request: Request) -> dict[str, Any]:
    return _controller(request).status(is_operator(request))


TOO_MANY = {429: {"model": ErrorBody, "description": "Too many requests without the operator "
                                                     "token (rig/web/ratelimit.py): retry after "
                                                     "the Retry-After seconds."},
            503: {"model": ErrorBody, "description": "The preview worker is busy: retry after "
                                                     "the Retry-After seconds."}}


@router.post("/plan/preview", response_model=PlanPreview,
             responses={**BAD_BODY, **CONFLICT, **TOO_MANY},
             summary="Preview a run or campaign: steps, estimated duration, fits the rig "
                     "(409 while a fault is latched)")
def preview(request: Request, body: RunRequest) -> dict[str, Any]:
    """Computed in the preview worker process (rig/web/workers.py: lower CPU priority, a
    bounded queue, 503 when full) from the rig's facts: never in the engine's process, never
    in this server's event loop. Token-less clients are rate-limited before this runs."""
    try:
        if pool_full("preview"):  # the engine is not even asked for the rig's facts
            raise PoolBusy("the preview worker is busy: retry in a second")
        facts = _do(_controller(request).preview_facts)
        # a plan of 100,000 steps holds no thread of this server (and its GIL) for seconds
        return run_in_worker(compute_preview, body, facts, pool="preview", timeout_s=120)
    except PoolBusy as exc:
        raise HTTPException(503, str(exc), headers={"Retry-After": "1"}) from exc
    except RigError as exc:
        raise HTTPException(409, str(exc)) from exc


NO_IDENTITY = {400: {"model": ErrorBody, "description": "The body could not be parsed (not "
                                                     "UTF-8 JSON), or it names no operator or "
                                                     "no unit serial (one line naming the "
                                                     "field)."}}


@router.post("/control/start", response_model=Message,
             responses={**AUTH, **CONFLICT, **NO_IDENTITY},
             summary="Start a run or a campaign (needs the input lock confirmed, the operator "
                     "and the unit's serial)")
def start(request: Request, body: RunRequest,
          _token: Operator) -> dict[str, Any]:
    """A result without who measured it or which unit it was is no result (a test station
    asks for both before a part is tested): 400 naming the missing field."""
    problem = start_identity_problem(body)
    if problem is not None:
        raise HTTPException(400, problem)
    return _do(lambda: _controller(request).start_measurement(body))


@router.post("/control/pause", response_model=Message, responses={**AUTH, **CONFLICT},
             summary="Pause at the next checkpoint (the torque is held)")
def pause(request: Request, _token: Operator) -> dict[str, Any]:
    return {"ok": True, "message": _do(_controller(request).pause)}


@router.post("/control/resume", response_model=Message, responses={**AUTH, **CONFLICT},
             summary="Resume a paused measurement")
def resume(request: Request, _token: Operator) -> dict[str, Any]:
    return {"ok": True, "message": _do(_controller(request).resume)}


@router.post("/control/abort", response_model=Message, responses={**AUTH, **CONFLICT},
             summary="Abort: safe state at once, the run kept as aborted")
def abort(request: Request, _token: Operator) -> dict[str, Any]:
    return {"ok": True, "message": _do(_controller(request).abort)}


_ESTOP = ThreadPoolExecutor(max_workers=2, thread_name_prefix="estop")
"""The E-stop's own threads: a full request thread pool (previews, history) never delays it."""


@router.post("/control/estop", response_model=Message,
             summary="E-stop: zero torque and the drive disabled, always (no token needed)")
async def estop(request: Request) -> dict[str, Any]:
    controller = _controller(request)
    message = await asyncio.get_running_loop().run_in_executor(_ESTOP, controller.estop)
    return {"ok": True, "message": message}


@router.post("/devices/tare", response_model=TareResult, responses={**AUTH, **CONFLICT},
             summary="Tare the torque transducer (unit unloaded, no measurement running)")
def tare(request: Request, _token: Operator) -> dict[str, Any]:
    offset = _do(_controller(request).tare)
    return {"ok": True, "offset_Nm": offset,
            "message": f"torque transducer tared (offset {offset:+.4f} N*m)"}


@router.post("/devices/reset-faults", response_model=ResetFaultsResult,
             responses={**AUTH, **CONFLICT, **BAD_BODY},
             summary="Acknowledge and reset latched faults (drive fault latch, E-stop); logged")
def reset_faults(request: Request, _token: Operator,
                 body: ResetFaultsRequest | None = None) -> dict[str, Any]:
    operator = body.operator if body is not None else None
    client = request.client.host if request.client else "?"
    who = f"{operator or 'operator token'} from {client}"
    return _do(lambda: _controller(request).reset_faults(who))


@router.post("/devices/input-lock", response_model=InputLockAnswer,
             responses={**AUTH, **CONFLICT, **BAD_BODY,
                        202: {"model": InputLockAnswer,
                              "description": "The input is moving to the lock angle "
                                             "(``moving``): progress on /api/live "
                                             "(``input_lock`` events) and /api/status; "
                                             "confirmed when it is locked."}},
             summary="Lock the input (motor) and confirm it, or withdraw the confirmation; "
                     "answers at once (202 while the input still moves)")
def input_lock(request: Request, body: InputLockRequest, _token: Operator) -> Any:
    """A short move's answer is its end (200); a longer one (a lock at +-3599 deg turns for
    10-20 s) answers at once with 202 and ``moving`` (issue 33 item 7). 409 while a lock
    move or a measurement is under way."""
    answer = _do(lambda: _controller(request).confirm_input_lock(body))
    if answer.get("moving"):
        return JSONResponse(InputLockAnswer(**answer).model_dump(), status_code=202)
    return answer


@router.get("/units", response_model=list[UnitExample],
            summary="Example units shipped with the package, of every unit kind the page "
                    "takes (seed 000 pairs, the seed 002 cycloid, the seed 001 beveloid, the "
                    "seed 003 planetary train)")
def units() -> list[dict[str, Any]]:
    """The example units, the seed 000 pairs first, then the cycloid, the beveloid and the
    planetary train."""
    folder = resources.files("rig.examples") / "units"
    out = []
    for item in sorted(folder.iterdir(), key=lambda p: p.name):
        if item.name.endswith(".json"):
            data = json.loads(item.read_text(encoding="utf-8"))
            if data.get("kind", "internal_involute") in UNIT_MODELS:
                out.append({"name": item.name[:-5], "unit": data})
    # by kind (the seed 000 pairs first: the page's default unit is the first), then name
    kinds = list(UNIT_MODELS)
    return sorted(out, key=lambda u: kinds.index(u["unit"].get("kind", "internal_involute")))


BAD_FILE = {400: {"model": ErrorBody, "description": "Not a valid campaign file (the message "
                                                    "names the file, line and column or key)."}}


@router.get("/campaign-files", response_model=list[CampaignFileName],
            summary="The rig's example campaigns (examples/campaigns), by name")
def campaign_file_names() -> list[dict[str, str]]:
    return campaign_files.example_list()


@router.get("/campaign-files/{name}", response_model=CampaignSetup,
            responses={404: {"model": ErrorBody, "description": "No such example campaign."},
                       **BAD_FILE},
            summary="An example campaign as the page's set-up (looked up by name, never a path)")
def campaign_file(name: Annotated[str, PathParam(pattern=NAME_PATTERN, max_length=80)]
                  ) -> dict[str, Any]:
    try:
        setup = campaign_files.example_setup(name)
    except CampaignError as exc:
        raise HTTPException(400, str(exc)) from exc
    if setup is None:
        raise HTTPException(404, f"no example campaign named {name!r}")
    return setup


@router.post("/campaign-upload", response_model=CampaignSetup,
             responses={**BAD_FILE, **BAD_BODY},
             summary="A campaign file the operator uploads, as the page's set-up (nothing is "
                     "stored or run)")
def campaign_file_upload(body: CampaignUpload) -> dict[str, Any]:
    try:
        return campaign_files.upload_setup(body.file_name, body.text)
    except CampaignError as exc:
        raise HTTPException(400, str(exc)) from exc

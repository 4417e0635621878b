"""Each operation's own error set in the OpenAPI document, instead of one list on every route.

What every request can meet comes first (:data:`ALWAYS`: keys and scopes, rate limits, an
internal error); a route with parameters or a body can meet a validation error (422), one with
a path parameter an unknown id (404); :data:`EXTRA` names what a handler raises beyond those
(a result not ready: 409, an upload too large: 413, ...). Every error body is
:class:`~app.api.schemas.ErrorOut` ``{detail, code}``; the codes are listed in docs/api.md.
A description a route gives for a status (e.g. the tolerance band's 404 "not computed") is kept.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.routing import APIRoute

from app.api.schemas import ERRORS, ErrorOut

ALWAYS = (401, 403, 429, 500)
DESCRIPTIONS = {
    400: "bad input (a parameter, a name or a file that is not what the route takes)",
    401: "an API key is needed, or the one sent is unknown or revoked",
    403: "the key's scope is too small, or a cross-site request",
    404: "not found (the id in the path, or what it names)",
    406: "the Accept header asks for a format the route does not give",
    408: "the request body stalled",
    409: "not ready or busy: the analysis or job behind it has not finished",
    413: "too large (body, file, or what it inflates to)",
    415: "a file format the route does not read",
    422: "invalid parameters, or input the analysis cannot use",
    429: "rate limited, or the job queue is full",
    500: "internal error",
    503: "the CAN bus or interface is not available",
    507: "the data directory is full",
}
RESULT = (406, 409)  # results of an analysis: 409 while it runs; CSV or JSON by Accept
EXTRA: dict[str, tuple[int, ...]] = {
    "POST /logs": (400, 408, 413, 415, 507),
    "POST /vehicles": (400, 408, 413, 507),
    "POST /analyses": (400, 404),
    "GET /analyses/{analysis_id}/events": RESULT,
    "GET /analyses/{analysis_id}/metrics": RESULT,
    "GET /analyses/{analysis_id}/speed": RESULT,
    "GET /analyses/{analysis_id}/events/{event}/speed": RESULT,
    "GET /analyses/{analysis_id}/signals": (409,),
    "GET /analyses/{analysis_id}/signals/{name}": RESULT,
    "GET /analyses/{analysis_id}/tolerance": (409,),
    "POST /analyses/{analysis_id}/tolerance": (409,),
    "GET /analyses/{analysis_id}/tolerance/status": (409,),
    "POST /analyses/{analysis_id}/diagnoses": (400, 409),
    "GET /diagnoses/{diagnosis_id}/plots/{name}": (409,),
    "GET /diagnoses/{diagnosis_id}/charts": (409,),
    "POST /diagnoses/{diagnosis_id}/apply": (400, 409, 507),
    "POST /diagnoses/{diagnosis_id}/validate": (409,),
    "POST /identifications": (400, 404),
    "GET /identifications/{identification_id}/vehicle": (409,),
    "POST /identifications/{identification_id}/apply": (400, 409, 507),
    "POST /batches": (400, 404),
    "POST /live/sessions": (400, 409, 503),
    "POST /live/sessions/{session_id}/stop": (503,),
    "GET /fleet": (404,),
    "GET /vehicles/{name}/compare": (400,),
    "POST /vehicles/{name}/gap-sensitivity": (409,),
}


def statuses(route: APIRoute) -> list[int]:
    """The error statuses ``route`` can answer with."""
    dep = route.dependant
    out = set(ALWAYS)
    if dep.path_params or dep.query_params or dep.header_params or dep.body_params:
        out.add(422)
    if dep.path_params:
        out.add(404)
    for method in route.methods or ():
        out.update(EXTRA.get(f"{method} {route.path}", ()))
    return sorted(out)


def apply(router: APIRouter) -> None:
    """Give every route of ``router`` its own error set (call before ``include_router``)."""
    shared = {id(v) for v in ERRORS.values()}
    for route in router.routes:
        if not isinstance(route, APIRoute):
            continue
        own: dict[int | str, Any] = {k: v for k, v in route.responses.items() if id(v) not in shared}
        for s in statuses(route):
            given = own.get(s) or own.get(str(s)) or {}
            own.pop(str(s), None)
            own[s] = {"model": ErrorOut, "description": given.get("description", DESCRIPTIONS[s]),
                      **{k: v for k, v in given.items() if k not in ("model", "description")}}
        route.responses = own

"""The dashboard's HTTP side: one page, a JSON view of the fleet, previews, landmarks.

Read-only by design: there is no route that changes anything.  Bound to 127.0.0.1 unless
told otherwise; binding elsewhere needs a token, which every request must then carry
(``Authorization: Bearer TOKEN`` or ``?token=TOKEN``); a wrong or missing token gets a bare
401 and nothing else.
"""

from __future__ import annotations

import asyncio
import hmac
import time
from importlib import resources
from typing import Any

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.base import BaseHTTPMiddleware, RequestResponseEndpoint
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, PlainTextResponse, Response
from starlette.routing import Route

from companion.monitoring.watcher import FleetView, MonitorWatcher, VehicleView

HISTORY_WINDOW_S = 60.0
LANDMARKS_REFRESH_S = 30.0


class TokenGate(BaseHTTPMiddleware):
    """Refuse every request without the right token (constant-time comparison)."""

    def __init__(self, app: Any, token: str) -> None:
        super().__init__(app)
        self._token = token.encode()

    async def dispatch(self, request: Request, call_next: RequestResponseEndpoint) -> Response:
        header = request.headers.get("authorization", "")
        given = header[7:] if header.lower().startswith("bearer ") else ""
        given = given or request.query_params.get("token", "")
        if not hmac.compare_digest(given.encode(), self._token):
            return PlainTextResponse("unauthorized", status_code=401)
        return await call_next(request)


def vehicle_json(view: VehicleView, now_s: float) -> dict[str, Any]:
    """One vehicle for the page: latest payloads, ages, counts, events, the last minute."""
    history = [
        {"age_s": round(now_s - t, 2), **pose}
        for t, pose in view.pose_history
        if now_s - t <= HISTORY_WINDOW_S and isinstance(pose, dict)
    ]
    return {
        "status": view.latest.get("status"),
        "pose": view.latest.get("pose"),
        "tracks": view.latest.get("tracks"),
        "age_s": {t: round(view.age_s(t, now_s) or 0.0, 2) for t in view.received_s},
        "counts": dict(view.counts),
        "events": list(view.events)[-10:],
        "has_preview": view.preview_jpeg is not None,
        "history": history[-1500:],
    }


def fleet_json(view: FleetView, now_s: float | None = None) -> dict[str, Any]:
    """The whole fleet as the page polls it."""
    now_s = time.monotonic() if now_s is None else now_s
    return {"vehicles": {vid: vehicle_json(v, now_s) for vid, v in sorted(view.vehicles.items())}}


def create_app(watcher: MonitorWatcher, token: str | None = None) -> Starlette:
    """The ASGI application over a running watcher."""
    page = resources.files("companion.dashboard").joinpath("page.html").read_text("utf-8")
    landmarks_cache: dict[str, tuple[float, Any]] = {}

    async def index(request: Request) -> Response:
        return HTMLResponse(page)

    async def fleet(request: Request) -> Response:
        return JSONResponse(fleet_json(watcher.snapshot()))

    async def preview(request: Request) -> Response:
        view = watcher.snapshot().vehicles.get(request.path_params["vehicle"])
        if view is None or view.preview_jpeg is None:
            return PlainTextResponse("no preview", status_code=404)
        return Response(view.preview_jpeg, media_type="image/jpeg",
                        headers={"Cache-Control": "no-store"})

    async def landmarks(request: Request) -> Response:
        vehicle = request.path_params["vehicle"]
        cached = landmarks_cache.get(vehicle)
        if cached is None or time.monotonic() - cached[0] > LANDMARKS_REFRESH_S:
            answer = await asyncio.to_thread(watcher.query, vehicle, "landmarks", 2.0)
            cached = (time.monotonic(), answer)
            if answer is not None:
                landmarks_cache[vehicle] = cached
        return JSONResponse({"landmarks": cached[1] or []})

    middleware = [Middleware(TokenGate, token=token)] if token else []
    return Starlette(
        routes=[
            Route("/", index),
            Route("/api/fleet", fleet),
            Route("/api/preview/{vehicle}", preview),
            Route("/api/landmarks/{vehicle}", landmarks),
        ],
        middleware=middleware,
    )

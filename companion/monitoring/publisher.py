"""The companion's side: publish status, pose, tracks, events, preview; answer queries.

Zenoh calls queryable handlers on its own threads; the handlers here only read values
that the application hands over as callables returning JSON-ready data.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from typing import Any

import zenoh

from companion.monitoring.config import MonitorConfig, open_session
from companion.monitoring.keys import QUERYABLES, TOPICS, key_for

log = logging.getLogger(__name__)

JsonProvider = Callable[[], Any]


class MonitorPublisher:
    """Publishes one vehicle's monitoring data on ``companion/<vehicle>/...``."""

    def __init__(self, cfg: MonitorConfig, vehicle_id: str,
                 providers: dict[str, JsonProvider] | None = None,
                 session: zenoh.Session | None = None) -> None:
        self.cfg = cfg
        self.vehicle_id = vehicle_id
        self._own_session = session is None
        self.session = session if session is not None else open_session(cfg)
        self.published = dict.fromkeys(TOPICS, 0)
        self._last_preview_s = 0.0
        self._publishers = {
            topic: self.session.declare_publisher(
                key_for(vehicle_id, topic),
                # status and events must arrive; a late preview is worth less than none
                congestion_control=zenoh.CongestionControl.DROP
                if topic == "preview"
                else zenoh.CongestionControl.BLOCK,
            )
            for topic in TOPICS
        }
        self._queryables = [
            self.session.declare_queryable(key_for(vehicle_id, name), self._answer(name, fn))
            for name, fn in (providers or {}).items()
            if name in QUERYABLES
        ]

    def _answer(self, name: str, provider: JsonProvider) -> Callable[[zenoh.Query], None]:
        key = key_for(self.vehicle_id, name)

        def handler(query: zenoh.Query) -> None:
            try:
                query.reply(key, json.dumps(provider(), default=str).encode())
            except Exception as err:  # a bad provider must not kill zenoh's thread
                log.warning("queryable %s failed: %s", key, err)
                query.reply_err(str(err).encode())

        return handler

    def publish_json(self, topic: str, data: Any) -> None:
        """Publish one JSON payload on ``companion/<vehicle>/<topic>``."""
        self._publishers[topic].put(json.dumps(data, default=str).encode())
        self.published[topic] += 1

    def preview_due(self, now_s: float | None = None) -> bool:
        """True when :meth:`publish_preview` would publish now."""
        now_s = time.monotonic() if now_s is None else now_s
        return now_s - self._last_preview_s >= 1.0 / self.cfg.preview_rate_hz

    def preview_wanted(self, now_s: float | None = None) -> bool:
        """Due (:meth:`preview_due`) and someone subscribes to the preview: a preview
        nobody watches is not drawn (its resize and JPEG encoding cost the frame's cores)."""
        if not self.preview_due(now_s):
            return False
        try:
            status = self._publishers["preview"].matching_status
        except zenoh.ZError:  # cannot tell: draw it
            return True
        # zenoh 1.x returns a MatchingStatus (its stubs say bool)
        return bool(getattr(status, "matching", status))

    def publish_preview(self, jpeg: bytes, now_s: float | None = None) -> bool:
        """Publish a JPEG preview unless one went out less than 1/rate ago."""
        now_s = time.monotonic() if now_s is None else now_s
        if not self.preview_due(now_s):
            return False
        self._last_preview_s = now_s
        self._publishers["preview"].put(jpeg)
        self.published["preview"] += 1
        return True

    def close(self) -> None:
        """Undeclare everything; close the session if this object opened it."""
        for q in self._queryables:
            q.undeclare()
        for p in self._publishers.values():
            p.undeclare()
        if self._own_session:
            self.session.close()

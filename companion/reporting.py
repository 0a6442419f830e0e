"""Fan-out of everything the pipeline reports: the flight log and Zenoh monitoring, and the
JSON of a frame's typed result (:func:`pose_json`, :func:`track_json`: docs/monitoring.md,
docs/flightlog.md).  The payload formats are a contract; they are built here only."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.perception_types import TrackView
from tracker.pose.types import PoseFix

if TYPE_CHECKING:  # the pipeline imports this module for the JSON: no zenoh for that
    from companion.flightlog import FlightLogWriter
    from companion.monitoring.publisher import MonitorPublisher

log = logging.getLogger(__name__)

#: Flight-log record kind for each monitoring topic.
LOG_KIND = {"status": "status", "pose": "fix", "tracks": "track", "events": "event"}


class Reporter:
    """Writes each report to the flight log and publishes it (either may be absent)."""

    def __init__(self, flightlog: FlightLogWriter | None,
                 monitor: MonitorPublisher | None) -> None:
        self.flightlog = flightlog
        self.monitor = monitor
        self.failures = 0
        self._told_flightlog_stopped = False

    def report(self, topic: str, t_us: int, data: dict[str, Any]) -> None:
        """Log and publish one payload; a failing sink is counted, never fatal."""
        if self.flightlog is not None:
            try:
                self.flightlog.write(LOG_KIND.get(topic, topic), t_us, **data)
            except (OSError, ValueError) as err:
                self.failures += 1
                log.warning("flight log write failed: %s", err)
            self._tell_flightlog_stopped(t_us)
        if self.monitor is not None:
            try:
                self.monitor.publish_json(topic, {"t_us": t_us, **data})
            except Exception as err:  # zenoh raises its own ZError
                self.failures += 1
                log.warning("monitor publish failed: %s", err)

    def _tell_flightlog_stopped(self, t_us: int) -> None:
        """Once, when the flight log stopped (full disk): an event on Zenoh, which still
        works, so whoever watches the flight sees it (docs/flightlog.md)."""
        failure = None if self.flightlog is None else self.flightlog.failure
        if failure is None or self._told_flightlog_stopped or self.monitor is None:
            return
        self._told_flightlog_stopped = True
        try:
            self.monitor.publish_json("events", {"t_us": t_us, "event": "flightlog-stopped",
                                                 "reason": failure})
        except Exception as err:  # zenoh raises its own ZError
            self.failures += 1
            log.warning("monitor publish failed: %s", err)

    def preview_due(self) -> bool:
        """True when a preview would be published now and someone watches it (so it is
        only drawn when needed)."""
        return self.monitor is not None and self.monitor.preview_wanted()

    def preview(self, jpeg: bytes) -> None:
        """Publish a preview JPEG (rate-limited by the publisher)."""
        if self.monitor is not None:
            try:
                self.monitor.publish_preview(jpeg)
            except Exception as err:  # zenoh raises its own ZError
                self.failures += 1
                log.warning("preview publish failed: %s", err)

    def close(self) -> None:
        """Flush and close both."""
        if self.flightlog is not None:
            self.flightlog.close()
        if self.monitor is not None:
            self.monitor.close()


def pose_json(fix: PoseFix) -> dict[str, Any]:
    """The monitoring payload of a fix (docs/monitoring.md, topic ``pose``); with
    ``sent_position_ned_m`` when the autopilot was sent another position (companion.fixgate:
    a fix stated worse than the autopilot can fuse, sent as its pull)."""
    out: dict[str, Any] = {
        "position_ned_m": [round(v, 4) for v in fix.position_ned_m],
        "attitude_rpy_rad": [round(v, 5) for v in fix.attitude_rpy_rad],
        "covariance_diag": [float(f"{v:.6g}") for v in np.diag(fix.covariance)],
        "quality": fix.quality,
        "landmark_ids": list(fix.landmark_ids),
        "solver": fix.solver,
        "attitude_prior": fix.attitude_prior,
    }
    if fix.sent_position_ned_m is not None:
        out["sent_position_ned_m"] = [round(v, 4) for v in fix.sent_position_ned_m]
    return out


def track_json(track: TrackView) -> dict[str, Any]:
    """One track of the ``tracks`` payload (docs/monitoring.md)."""
    return {"landmark_id": track.landmark_id, "box": [round(v, 1) for v in track.box],
            "confidence": round(track.confidence, 3), "features": list(track.features),
            "corners": None if track.corners is None else np.round(track.corners, 2).tolist()}


def tracks_json(tracks: Iterable[TrackView]) -> list[dict[str, Any]]:
    """The ``tracks`` payload's list of tracks."""
    return [track_json(t) for t in tracks]

"""Plain-text rendering of a :class:`FleetView` for the terminal monitor."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.monitoring.watcher import FleetView, VehicleView

STALE_AFTER_S = 3.0


def _num(value: Any, fmt: str = ".1f") -> str:
    return format(value, fmt) if isinstance(value, int | float) else "-"


def _age(view: VehicleView, topic: str) -> str:
    age = view.age_s(topic)
    if age is None:
        return "never"
    return f"STALE {age:.0f} s" if age > STALE_AFTER_S else f"{age:.1f} s ago"


def render_vehicle(view: VehicleView) -> list[str]:
    """A few lines about one vehicle; stale data says so with its age."""
    status: Mapping[str, Any] = view.latest.get("status", {})
    latency = status.get("latency_ms", {})
    lines = [
        f"vehicle {view.vehicle_id}: {status.get('state', '?')}  "
        f"(status {_age(view, 'status')})",
        f"  fps {_num(status.get('fps'))}  latency p50 {_num(latency.get('p50'))} ms "
        f"p99 {_num(latency.get('p99'))} ms  link {status.get('link', '-')}  "
        f"dropped frames {status.get('dropped_frames', '-')}",
    ]
    streams = status.get("autopilot_streams", {})
    if streams:
        lines.append("  streams " + "  ".join(
            f"{name} {s.get('state', '?')} {_num(s.get('rate_hz'))}/{_num(s.get('asked_hz'), 'g')}"
            " Hz" for name, s in sorted(streams.items())))
    for warning in status.get("warnings", []):
        lines.append(f"  WARNING {warning}")
    cause = status.get("no_fix_cause")
    if isinstance(cause, dict):
        lines.append(f"  no fix can come: {cause.get('cause')}: {cause.get('detail')}")
    counters = status.get("counters", {})
    if counters:
        lines.append("  " + "  ".join(f"{k} {v}" for k, v in sorted(counters.items())))
    pose = view.latest.get("pose")
    if pose:
        ned = pose.get("position_ned_m", [None] * 3)
        lines.append(f"  pose N {_num(ned[0], '.2f')} E {_num(ned[1], '.2f')} "
                     f"D {_num(ned[2], '.2f')} m  quality {_num(pose.get('quality'), '.2f')}  "
                     f"landmarks {','.join(map(str, pose.get('landmark_ids', [])))}  "
                     f"({_age(view, 'pose')})")
    tracks = view.latest.get("tracks")
    if isinstance(tracks, dict):
        items = tracks.get("tracks", [])
        lines.append(f"  tracks {len(items)}: " + ", ".join(
            f"{t.get('landmark_id')} {_num(t.get('confidence'), '.2f')}" for t in items))
    for event in view.events[-3:]:
        lines.append(f"  event {event}")
    if view.preview_jpeg:
        lines.append(f"  preview {len(view.preview_jpeg)} bytes ({_age(view, 'preview')})")
    return lines


def render_fleet(view: FleetView) -> str:
    """Every vehicle, sorted by id."""
    if not view.vehicles:
        return "no companion seen yet"
    out: list[str] = []
    for vid in sorted(view.vehicles):
        out.extend(render_vehicle(view.vehicles[vid]))
    return "\n".join(out)

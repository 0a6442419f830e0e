"""Scoring a replay against the stream's ``truth_pose.csv`` (``companion replay``).

The keys of ``companion demo --json`` (:func:`companion.demo.summary`: RMSE, NEES share,
latency ...) plus what a recording needs:

* ``frames_2plus_visible``: frames of the stream on which at least two landmarks are
  *fully visible* by the truth: each landmark's four corners, projected with the true pose
  and the stream's camera, in front of the camera and inside the image;
* ``fix_share_2plus_visible``: the share of those that got a fix (solved, before the
  bridge; a frame dropped in real time counts as without);
* ``nees_inside_95_share``: fixes whose 3-DOF NEES lies inside the two-sided 95 % bound;
* ``fixes_solved``, ``fixes_refused`` by reason (the bridge's), ``attitude_error_deg``: the
  attitude the solver was given against the true one (RMS per axis, and the mean yaw);
* ``longest_wrong_track_frames``: the longest run of frames one track sat on a wrong place
  (its box's part in the image overlaps its landmark's true box, the projected corners'
  bounding box cut to the image, at IoU < ``WRONG_IOU``, or its landmark is not in view);
* ``longest_fix_gap_s``: the longest time (recorded) between two frames with a fix, from
  the first fix to the stream's last frame, and ``longest_fix_gap_at_s`` where it began
  (issue 19's proof measures the same between fused fixes);
* ``light_steps``: each frame whose mean grey level jumped by ``LIGHT_STEP`` or more from
  the frame before (recorded time ``at_s``) and ``fix_after_s``, the recorded time from it
  to the next fix (0: that frame had one; None: none came).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from companion.app import CompanionApp, Frame, FrameResult
from companion.autopilot import outcome_lines
from companion.core.stream_format import TruthPose
from companion.demo import print_summary, summary
from companion.observers import FixTruths
from companion.recorded import RecordedTruth
from companion.sensors import SensorHistory
from mavlink_bridge.bridge import VisionBridge
from mavlink_bridge.fake_autopilot import FakeAutopilot
from tracker.boxes import box_iou
from tracker.camera import CameraModel
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import MapLandmark

#: A track overlapping its landmark's true box less than this is on a wrong place.
WRONG_IOU = 0.2
#: A frame this much brighter or darker (mean grey) than the one before is a light step.
LIGHT_STEP = 1.25


class ReplayScorer(FixTruths):
    """The demo's truth observer on a recording, plus which frames got a fix, the tracks
    on a wrong place, the light steps and the attitude the solver was given (``sensors``:
    the flight's side sensors).  Observes the flight's results; its scoring of a frame is
    done when ``on_result`` returns (``--fast`` lets the next frame in only after that:
    :class:`companion.replay.ReplaySource`, observing after it)."""

    def __init__(self, truth: RecordedTruth, camera: CameraModel,
                 landmarks: Sequence[MapLandmark], sensors: SensorHistory) -> None:
        super().__init__(lambda f: truth.position(f.t_us), landmarks)
        self.truth = truth
        self.camera = camera
        self.sensors = sensors
        self.fixed: set[int] = set()
        self.attitude_errors: list[tuple[float, float, float]] = []
        self.wrong_run: dict[str, int] = {}
        self.longest_wrong = 0
        self._level: float | None = None
        self.light_steps: list[dict[str, float | None]] = []
        self.gaps = GapMeter()

    def on_result(self, frame: Frame, result: FrameResult) -> None:
        super().on_result(frame, result)
        if result.fix is not None:
            self.fixed.add(frame.index)
        found = self.truth.pose_at(frame.t_us)
        if found is not None:
            self._score_tracks(found[1], result)
            self._score_light(frame, found[0] / 1e6, result.fix is not None)
            self.gaps.add(found[0] / 1e6, result.fix is not None)
        given = self.sensors.attitude_at(frame.t_us)
        if found is not None and given is not None:
            p = found[1]
            self.attitude_errors.append(tuple(  # type: ignore[arg-type]
                math.degrees(math.remainder(g - t, math.tau)) for g, t in
                ((given.roll_rad, p.roll_rad), (given.pitch_rad, p.pitch_rad),
                 (given.yaw_rad, p.yaw_rad))))

    def _score_tracks(self, pose: TruthPose, result: FrameResult) -> None:
        """Advance each live track's run of frames on a wrong place (module notes); a bad
        frame (no tracks reported) leaves the runs as they are."""
        if result.bad_frame:
            return
        boxes = track_boxes(result)
        position = self.truth.to_flight((pose.north_m, pose.east_m, pose.down_m))
        rpy = (pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
        for lid in [i for i in self.wrong_run if i not in boxes]:
            del self.wrong_run[lid]
        for lid, box in boxes.items():
            lm = self.landmarks.get(lid)
            true = None if lm is None else true_box(self.camera, position, rpy, lm)
            on = on_its_landmark(box, true, self.camera)
            self.wrong_run[lid] = 0 if on else self.wrong_run.get(lid, 0) + 1
            self.longest_wrong = max(self.longest_wrong, self.wrong_run[lid])

    def _score_light(self, frame: Frame, r_s: float, fixed: bool) -> None:
        """Note a light step, and the time from each step to its next fix."""
        level = max(float(frame.image[::8, ::8].mean()), 1.0)
        last, self._level = self._level, level
        if last is not None and max(level / last, last / level) >= LIGHT_STEP:
            self.light_steps.append({"at_s": round(r_s, 3), "fix_after_s": None})
        for step in self.light_steps:
            if fixed and step["fix_after_s"] is None:
                step["fix_after_s"] = round(r_s - float(step["at_s"] or 0.0), 3)


class GapMeter:
    """The longest time without a fix: from each fix to the next frame with one, or to the
    last frame seen; nothing before the first fix."""

    def __init__(self) -> None:
        self._last_fix_s: float | None = None
        self.longest_s = 0.0
        self.began_s: float | None = None  # where the longest began (the fix before it)

    def add(self, t_s: float, fixed: bool) -> None:
        """A frame at ``t_s`` (s), with a fix or not."""
        if self._last_fix_s is not None and t_s - self._last_fix_s > self.longest_s:
            self.longest_s, self.began_s = t_s - self._last_fix_s, self._last_fix_s
        if fixed:
            self._last_fix_s = t_s


def track_boxes(result: FrameResult) -> dict[str, tuple[float, float, float, float]]:
    """Landmark id -> box (x, y, w, h) of each track still live after the frame: those the
    result reports less those it reports lost (a track dropped after its fix is reported
    with its box and its ``lost`` event in the same frame; its landmark's next track is
    another track, whose run starts afresh)."""
    lost = {e.get("landmark") for e in result.events if e.get("event") == "lost"}
    out = {}
    for t in result.tracks:
        if t.landmark_id not in lost:
            x, y, w, h = (float(v) for v in t.box)
            out[t.landmark_id] = (x, y, w, h)
    return out


def true_box(camera: CameraModel, position_ned: Sequence[float],
             rpy_rad: tuple[float, float, float], landmark: MapLandmark
             ) -> tuple[float, float, float, float] | None:
    """The bounding box of ``landmark``'s projected corners cut to the image (x, y, w, h);
    None when a corner is behind the camera or nothing of the box is in the image."""
    pts = camera.world_to_camera(landmark_corners_ned(landmark), np.asarray(position_ned),
                                 rpy_rad)
    if not np.all(pts[:, 2] > 0):
        return None
    uv = camera.project_camera_points(pts)
    x0, y0 = float(uv[:, 0].min()), float(uv[:, 1].min())
    return in_image((x0, y0, float(uv[:, 0].max()) - x0, float(uv[:, 1].max()) - y0),
                    camera)


def on_its_landmark(box: Sequence[float], true: tuple[float, float, float, float] | None,
                    camera: CameraModel) -> bool:
    """Is a track's ``box`` on its landmark, whose true box (:func:`true_box`) is ``true``
    (None: not in view)?  Its part in the image must overlap the true box at IoU
    ``WRONG_IOU`` or more."""
    seen = in_image(box, camera)
    return true is not None and seen is not None and box_iou(seen, true) >= WRONG_IOU


def in_image(box: Sequence[float], camera: CameraModel
             ) -> tuple[float, float, float, float] | None:
    """The part of ``box`` (x, y, w, h) inside the image, None when nothing is: a track's
    box is scored on it as the true box is, since a tracker box following a plate out of
    the image reaches past the edge where the plate's true box is cut."""
    x0, y0 = max(float(box[0]), 0.0), max(float(box[1]), 0.0)
    x1 = min(float(box[0] + box[2]), camera.width - 1.0)
    y1 = min(float(box[1] + box[3]), camera.height - 1.0)
    return None if x1 <= x0 or y1 <= y0 else (x0, y0, x1 - x0, y1 - y0)


def fully_visible(camera: CameraModel, position_ned: Sequence[float],
                  rpy_rad: tuple[float, float, float], landmark: MapLandmark) -> bool:
    """All four corners of ``landmark`` in front of the camera and inside the image."""
    pts = camera.world_to_camera(landmark_corners_ned(landmark), np.asarray(position_ned),
                                 rpy_rad)
    if not np.all(pts[:, 2] > 0):
        return False
    uv = camera.project_camera_points(pts)
    return bool(np.all((uv[:, 0] >= 0) & (uv[:, 0] <= camera.width - 1)
                       & (uv[:, 1] >= 0) & (uv[:, 1] <= camera.height - 1)))


def visible_counts(truth: RecordedTruth, camera: CameraModel,
                   landmarks: Sequence[MapLandmark]) -> dict[int, int]:
    """Per frame index of ``truth_pose.csv``: how many landmarks are fully visible."""
    out = {}
    for index, (_, p) in truth.poses.items():
        position = truth.to_flight((p.north_m, p.east_m, p.down_m))
        rpy = (p.roll_rad, p.pitch_rad, p.yaw_rad)
        out[index] = sum(fully_visible(camera, position, rpy, lm) for lm in landmarks)
    return out


def _attitude_error(errors: list[tuple[float, float, float]]) -> dict[str, float] | None:
    if not errors:
        return None
    e = np.asarray(errors)
    rms = np.sqrt(np.mean(np.square(e), axis=0))
    return {"roll_rms": round(float(rms[0]), 3), "pitch_rms": round(float(rms[1]), 3),
            "yaw_rms": round(float(rms[2]), 3), "yaw_mean": round(float(np.mean(e[:, 2])), 3)}


def replay_summary(app: CompanionApp, fake: FakeAutopilot, bridge: VisionBridge,
                   scorer: ReplayScorer, source: Any, cpu_cores_busy: float,
                   visible: dict[int, int], facts: dict[str, Any]) -> dict[str, Any]:
    """The demo's summary keys plus the recording's (module doc)."""
    s = summary(app, fake, bridge, scorer, source, cpu_cores_busy, cpu_cores_busy)
    two = [i for i, n in visible.items() if n >= 2]
    outcomes = dict(getattr(app.sink, "results", {}))
    refused = {k: v for k, v in sorted(outcomes.items()) if k != "sent"}
    return {
        **facts, **s,
        "frames_in_stream": len(visible) or None,
        "frames_2plus_visible": len(two),
        "fix_share_2plus_visible": round(sum(i in scorer.fixed for i in two) / len(two), 3)
        if two else None,
        "nees_inside_95_share": s["nees_inside_95"],
        "fixes_solved": len(scorer.fixes),
        "fixes_refused": refused,
        "attitude_error_deg": _attitude_error(scorer.attitude_errors),
        "telemetry_replayed": dict(fake.replay.sent) if fake.replay is not None else {},
        "longest_wrong_track_frames": scorer.longest_wrong,
        "longest_fix_gap_s": round(scorer.gaps.longest_s, 3),
        "longest_fix_gap_at_s": None if scorer.gaps.began_s is None
        else round(scorer.gaps.began_s, 3),
        "light_steps": scorer.light_steps,
    }


def print_replay(s: dict[str, Any], out: Any = sys.stdout) -> None:
    """The human-readable end of ``companion replay``."""
    def f(v: Any) -> str:
        return "-" if v is None else str(v)

    print(f"replay            {s['stream']} ({s['mode']}); attitude from {s['attitude']}",
          file=out)
    print_summary(s, out)
    line, none_sent = outcome_lines({**s["fixes_refused"], "sent": s["fixes_sent"]})
    lines = [
        f"fully visible     {s['frames_2plus_visible']} frames with >= 2 landmarks, "
        f"{f(s['fix_share_2plus_visible'])} of them with a fix",
        f"fixes solved      {s['fixes_solved']}: {line}",
        f"longest gap       {s['longest_fix_gap_s']} s without a fix (from "
        f"{f(s['longest_fix_gap_at_s'])} s)",
        *([f"WARNING           {none_sent}"] if none_sent else []),
        f"attitude given    {f(s['attitude_error_deg'])} deg against the truth",
    ]
    print("\n".join(lines), file=out)

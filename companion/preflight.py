"""The preflight (``companion check``): one verdict per thing a flight depends on.

Each check returns a :class:`Check` (pass, warn or fail, and the reason in one line); the
command prints one line per check and exits 1 when any failed.  The camera and the link
are really opened: a check that only read the configuration would pass a camera that is
unplugged or a serial port that nobody answers on.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from companion.errors import CompanionError
from companion.flightmap import load_practical_map
from companion.runtime import bridge_for
from companion.settings import BUILT_IN, Settings
from companion.sources.base import EndOfStream
from companion.sources.factory import open_source, resolve
from mavlink_bridge.bridge import VisionBridge
from mavlink_bridge.errors import MavlinkBridgeError
from mavlink_bridge.params import profile_parameters, read_parameters, same_value
from tracker.acquire import ReferenceMatcher
from tracker.camera import CameraModel

Verdict = Literal["pass", "warn", "fail"]
#: The slowest fix rate the autopilots fuse: PX4's EKF2 ignores external vision more than
#: 200 ms apart (EV_MAX_INTERVAL, docs/deploy.md); ArduPilot's EKF3 calls the sensor
#: unhealthy after 300 ms.
MIN_FPS = {"ardupilot": 1000.0 / 300.0, "px4": 5.0}
#: How far the measured frame rate may be from ``source.camera_fps`` before the camera line
#: warns (30 frames of a live camera measure its rate to a few per cent).
CAMERA_FPS_TOLERANCE = 0.15
#: MAV_AUTOPILOT of each profile's HEARTBEAT (common.xml: ARDUPILOTMEGA 3, PX4 12).
AUTOPILOT_IDS = {"ardupilot": 3, "px4": 12}
AUTOPILOT_NAMES = {3: "ArduPilot", 12: "PX4"}


@dataclass(frozen=True)
class Check:
    """One line of the preflight."""

    name: str
    verdict: Verdict
    detail: str

    def line(self) -> str:
        """E.g. ``pass  camera: 640x480 at 30.0 fps, as the camera file says``."""
        return f"{self.verdict.upper() if self.verdict == 'fail' else self.verdict:<5} " \
               f"{self.name}: {self.detail}"


@dataclass(frozen=True)
class FrameSample:
    """What the source delivered: size of its frames and their rate."""

    frames: int
    size: tuple[int, int] | None
    fps: float


def check_noise(settings: Settings) -> Check:
    """Measured pixel noise, or the conservative default (a warning, not a failure)."""
    sigma = settings.pose.pixel_sigma_px
    if settings.noise_measured:
        return Check("noise", "pass", f"pose.pixel_sigma_px = {sigma:g} from "
                     f"{settings.origin_of('pose.pixel_sigma_px')}")
    return Check("noise", "warn", f"uncalibrated noise: pose.pixel_sigma_px = {sigma:g} is the "
                 "conservative default (measure it: companion calibrate noise)")


def check_camera_file(settings: Settings) -> Check:
    """The intrinsics come from a camera file and fit their own image size."""
    cam, origin = settings.camera, settings.origin_of("camera.fx")
    if origin == BUILT_IN:
        return Check("camera file", "fail", "no camera file: the built-in 640x480 model is not "
                     "your camera (companion calibrate camera writes one)")
    problem = intrinsics_problem(cam)
    if problem:
        return Check("camera file", "fail", f"{origin}: {problem}")
    fov = math.degrees(2 * math.atan(cam.width / (2 * cam.fx)))
    return Check("camera file", "pass", f"{origin}: {cam.width}x{cam.height}, fx {cam.fx:.1f} "
                 f"({fov:.0f} deg across), principal point ({cam.cx:.1f}, {cam.cy:.1f})")


def intrinsics_problem(cam: CameraModel) -> str:
    """Why these intrinsics cannot belong to a ``width`` x ``height`` image ("" if they can)."""
    w, h = cam.width, cam.height
    if abs(cam.cx - (w - 1) / 2) > 0.1 * w or abs(cam.cy - (h - 1) / 2) > 0.1 * h:
        return (f"principal point ({cam.cx:.1f}, {cam.cy:.1f}) is far from the centre of a "
                f"{w}x{h} image: the intrinsics were measured at another resolution")
    if not 0.8 < cam.fx / cam.fy < 1.25:
        return f"fx {cam.fx:.1f} and fy {cam.fy:.1f} differ by more than 25 %"
    fov = math.degrees(2 * math.atan(w / (2 * cam.fx)))
    if not 10.0 <= fov <= 170.0:
        return f"fx {cam.fx:.1f} gives {fov:.0f} deg across {w} px: not a real lens"
    return ""


async def sample_frames(settings: Settings, count: int = 30, timeout_s: float = 10.0
                        ) -> FrameSample:
    """Open the configured source and read ``count`` frames (recordings unpaced)."""
    config = dataclasses.replace(resolve(settings.source), realtime=False)
    source = await open_source(config)
    times: list[int] = []
    size = None
    deadline = time.monotonic() + timeout_s
    try:
        while len(times) < count and time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(source.recv(), deadline - time.monotonic())
            except (EndOfStream, TimeoutError):
                break
            times.append(frame.t_us)
            size = (frame.image.shape[1], frame.image.shape[0])
    finally:
        source.close()
    span = (times[-1] - times[0]) / 1e6 if len(times) > 1 else 0.0
    return FrameSample(len(times), size, (len(times) - 1) / span if span > 0 else 0.0)


def check_frames(settings: Settings, sample: FrameSample) -> Check:
    """Frames arrive, at the camera file's size and fast enough for the autopilot's EKF."""
    cam, spec = settings.camera, f"{settings.source.kind}:{settings.source.spec}"
    if sample.size is None:
        return Check("camera", "fail", f"{spec}: no frames")
    w, h = sample.size
    if (w, h) != (cam.width, cam.height):
        return Check("camera", "fail", f"{spec}: frames are {w}x{h}, the camera file "
                     f"({settings.origin_of('camera.width')}) says {cam.width}x{cam.height}")
    need = MIN_FPS[settings.vehicle.profile]
    if sample.fps < need:
        return Check("camera", "fail", f"{spec}: {sample.fps:.1f} fps, under the {need:.1f} "
                     f"fixes per second the {settings.vehicle.profile} EKF needs")
    asked = settings.source.camera_fps if resolve(settings.source).kind == "camera" else 0.0
    if asked and abs(sample.fps - asked) > CAMERA_FPS_TOLERANCE * asked:
        return Check("camera", "warn", f"{spec}: {w}x{h} at {sample.fps:.1f} fps, not the "
                     f"{asked:g} fps source.camera_fps asks (the driver keeps to its modes' "
                     "rates: v4l2-ctl --list-formats-ext)")
    return Check("camera", "pass", f"{spec}: {w}x{h} at {sample.fps:.1f} fps "
                 f"({sample.frames} frames), as the camera file says")


def check_landmarks(settings: Settings) -> Check:
    """Every landmark of the practical map has a reference image the matcher can find."""
    pmap = load_practical_map(settings)
    if not pmap.landmarks:
        return Check("landmarks", "fail", f"{settings.landmarks.map_path}: no landmarks")
    matcher = ReferenceMatcher(settings.acquire)
    problems = []
    for lm in pmap.landmarks:
        image = pmap.references.get(lm.landmark_id)
        if image is None:
            why = pmap.unusable.get(lm.landmark_id, "no appearance image")
            problems.append(f"{lm.landmark_id}: {why}")
            continue
        try:
            ref = matcher.add(lm.landmark_id, image)
        except ValueError as err:
            problems.append(f"{lm.landmark_id}: {str(err).removeprefix('image_bgr: ')}")
            continue
        if not ref.matchable:
            problems.append(f"{lm.landmark_id}'s image has {len(ref.keypoints_px)} features "
                            f"(the matcher needs {settings.acquire.min_inliers})")
    if problems:
        return Check("landmarks", "fail", "; ".join(problems))
    return Check("landmarks", "pass", f"{len(pmap.landmarks)} in the map, each with a "
                 "reference image the matcher accepts")


async def check_autopilot(settings: Settings, timeout_s: float, streams_s: float = 3.0
                          ) -> list[Check]:
    """The link, the streams the configuration needs, the profile's parameters: one bridge
    session, opened as ``companion run`` opens it (it asks for the streams on link-up)."""
    bridge = bridge_for(settings)
    started = time.monotonic()
    await bridge.start()
    try:
        link = await check_link(bridge, settings, timeout_s, started)
        if link.verdict == "fail":
            return no_link(link)
        up = time.monotonic()
        params = await check_parameters(bridge, settings)
        await asyncio.sleep(max(0.0, streams_s - (time.monotonic() - up)))
        return [link, check_streams(bridge), params]
    finally:
        await bridge.stop()


def no_link(link: Check) -> list[Check]:
    """A failed link, and the two checks that needed it."""
    return [link, Check("streams", "fail", "no link"), Check("parameters", "fail", "no link")]


async def check_link(bridge: VisionBridge, settings: Settings, timeout_s: float,
                     started: float) -> Check:
    """The autopilot answers with a heartbeat of the configured profile's kind."""
    endpoint = settings.mavlink.endpoint
    if not await bridge.wait_link(True, timeout_s):
        return Check("link", "fail", f"{endpoint}: no autopilot heartbeat in {timeout_s:g} s")
    waited = time.monotonic() - started
    beat = bridge.latest("HEARTBEAT")
    kind = getattr(beat.value if beat is not None else None, "autopilot", None)
    want = AUTOPILOT_IDS[settings.vehicle.profile]
    if kind != want:
        name = AUTOPILOT_NAMES.get(kind or -1, f"MAV_AUTOPILOT {kind}")
        return Check("link", "fail", f"{endpoint}: the autopilot is {name}, "
                     f"vehicle.profile = {settings.vehicle.profile}")
    return Check("link", "pass", f"{endpoint}: {AUTOPILOT_NAMES[want]} heartbeat after "
                 f"{waited:.1f} s")


def check_streams(bridge: VisionBridge) -> Check:
    """Every stream the configuration asks for arrives at its asked rate
    (mavlink_bridge.streams judges "arriving")."""
    report = bridge.stream_report()
    if not report:
        return Check("streams", "warn", "this configuration asks for no stream")
    bad = [f"{name} {r['state']} ({r['rate_hz']:g} of {r['asked_hz']:g} Hz)"
           for name, r in report.items() if r["state"] != "arriving"]
    if bad:
        return Check("streams", "fail", "; ".join(bad) + " (docs/mavlink.md, streams)")
    return Check("streams", "pass", ", ".join(f"{name} {r['rate_hz']:g} Hz"
                                              for name, r in report.items()))


async def check_parameters(bridge: VisionBridge, settings: Settings) -> Check:
    """The autopilot's parameters are the profile's (mavlink_bridge.params); the delay only
    needs an answer: its value is the measured latency, which the preflight cannot know."""
    link = getattr(bridge, "link", None)
    if link is None:
        return Check("parameters", "fail", "reading parameters needs mavlink.backend = "
                     "\"pymavlink\"")
    profile = settings.vehicle.profile
    wanted = profile_parameters(profile)
    delay = {k for k, v in profile_parameters(profile, 0.0).items()
             if v != profile_parameters(profile, 1.0)[k]}
    got = await read_parameters(link, list(wanted), profile)
    bad = [f"{name} {'no answer' if got[name] is None else f'{got[name]:g}'} (wants {v:g})"
           for name, v in wanted.items()
           if got[name] is None or (name not in delay and not same_value(got[name] or 0.0, v))]
    if bad:
        return Check("parameters", "fail", "; ".join(bad) + " (companion autopilot setup)")
    shown = ", ".join(f"{n} {got[n]:g}" for n in sorted(delay))
    return Check("parameters", "pass", f"{len(wanted)} as the {profile} profile wants "
                 f"({shown} ms)")


def guarded(name: str, error: CompanionError) -> Check:
    """A check that could not run is a failed check, with the error's one line."""
    return Check(name, "fail", str(error))


async def run_checks(settings: Settings, link_timeout_s: float = 5.0) -> Sequence[Check]:
    """Every check, in the order a user fixes things."""
    out = [check_noise(settings), check_camera_file(settings)]
    try:
        out.append(check_frames(settings, await sample_frames(settings)))
    except CompanionError as err:
        out.append(guarded("camera", err))
    try:
        out.append(check_landmarks(settings))
    except CompanionError as err:
        out.append(guarded("landmarks", err))
    try:
        out.extend(await check_autopilot(settings, link_timeout_s))
    except (CompanionError, MavlinkBridgeError, ValueError) as err:  # an absent serial port,
        # a configuration the bridge refuses (mavlink_bridge raises ValueError for those)
        out.extend(no_link(Check("link", "fail", str(err))))
    return out

"""The corners' noise model: the 1-sigma a perception states for a plate's corners.

No frames, no threads (it reads the tracks it is given; :meth:`CornerNoise.learn` writes
each track's learnt residuals, ``Track.residual_var`` and ``Track.bias_modes``): from the
corners' size in the image, the rectification's stretch there, the alignment's own fit,
saturation, the residuals the corners really showed in fixes from two or more plates (issue
25), and, for a plate cut by the image's edge, which corners are measured (issue 19).  A
frame's only plate with corners has them taken less the steady error it showed beside
other plates (:meth:`CornerNoise.alone`).
:class:`companion.perception.Perception` keeps the tracks and asks this model;
docs/pose.md ("Corner noise") says where each term comes from.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from companion.perception_types import FloatArray, PerceptionConfig, Track
from tracker.boxes import in_view_share, inside
from tracker.camera import CameraModel, Rectifier
from tracker.pose.config import PoseConfig
from tracker.pose.inputs import outline_basis
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.types import MapLandmark, Observation, PoseFix

#: A cut plate's corner is measured when its outline puts it this far inside the image (px).
EDGE_MARGIN_PX = 3.0
#: Parameters a fix fits to its corners (position and attitude).
POSE_PARAMETERS = 6


def cornered(observations: Sequence[Observation]) -> list[int]:
    """The indices of the observations that have corners (one: a lone plate's fix)."""
    return [i for i, o in enumerate(observations) if o.corners_px is not None]


class CornerNoise:
    """The corner sigma of a plate seen by ``camera`` (rectified by ``rectify`` if any).

    It holds the configurations it was given: a perception whose ``config`` is replaced
    later builds a new model (``Perception.noise``) for the change to reach it."""

    def __init__(self, camera: CameraModel, config: PerceptionConfig, pose_config: PoseConfig,
                 rectify: Rectifier | None, landmarks: Sequence[MapLandmark],
                 grey_plates: frozenset[str] = frozenset()) -> None:
        self.camera = camera
        self.config = config
        self.pose_config = pose_config
        self.rectify = rectify
        self.landmarks = list(landmarks)
        #: the landmarks whose running tracks align on grey levels alone
        #: (:func:`companion.corners.grey_aligned`), stated by their fit (``grey_fit_sigma``)
        self.grey_plates = grey_plates
        #: whether the frame being processed came through a lossy codec (``Frame.lossy``)
        self.lossy = False

    def cut(self, track: Track) -> tuple[tuple[bool, bool, bool, bool] | None, float] | None:
        """Which of a track's corners are measured (None: all four) and the factor on their
        sigma; None when none is.  In view by ``min_corner_in_view`` or more: all four, as
        they are.  Less: the corners inside the image by ``EDGE_MARGIN_PX``, their sigma
        grown by ``1 / sqrt(share in view)`` (the alignment rests on that part of the plate
        only: fewer pixels, and none around the corners outside).  None too for an outline
        with a corner more than one image size out of the image: a plate seen nearly edge-on
        or a cut plate's alignment run away; its centre would be as far out, and the pose
        solver refuses the whole frame for one such observation."""
        assert track.corners is not None
        size = (self.camera.width, self.camera.height)
        if not inside(track.corners + np.array(size), 3 * size[0], 3 * size[1], margin=0.0):
            return None  # beyond one image size out (the pose solver's bound): edge-on or run away
        share = in_view_share(track.corners, *size)
        if share >= self.config.min_corner_in_view:
            return None, 1.0
        flags = tuple(bool(inside(np.asarray([c]), *size, margin=EDGE_MARGIN_PX))
                      for c in track.corners)
        if share <= 0.0 or not any(flags):
            return None
        return (flags[0], flags[1], flags[2], flags[3]), 1.0 / float(np.sqrt(share))

    def unsettled(self, track: Track) -> bool:
        """A plate whose outline crosses the image's edge (a corner within
        ``EDGE_MARGIN_PX`` of it or beyond) in its track's first ``young_cut_frames``: its
        outline was aligned from a guess on the part in view and has not settled
        (``young_cut_sigma_rel``)."""
        if track.corners is None or track.frames >= self.config.young_cut_frames:
            return False
        quad = np.asarray(track.corners, np.float64)
        return not inside(quad, self.camera.width, self.camera.height, margin=EDGE_MARGIN_PX)

    def fits(self, track: Track) -> bool:
        """The alignment's fit sigma is within ``max_fit_sigma_ratio`` of the size model's."""
        if track.fit_sigma is None or track.corners is None:
            return True
        corners = [(float(u), float(v)) for u, v in track.corners]
        model = self.sigma(corners) or 0.0
        return track.fit_sigma <= self.config.max_fit_sigma_ratio * model

    def stretch(self, corners: Sequence[tuple[float, float]]) -> float:
        """Rectified px per raw px at the plate's centre (1 without rectification)."""
        if self.rectify is None:
            return 1.0
        centre = np.asarray(corners, np.float64).mean(axis=0)
        return self.rectify.scale_at((float(centre[0]), float(centre[1])))

    def sigma(self, corners: Sequence[tuple[float, float]] | None,
                      s: float | None = None, fit: float | None = None) -> float | None:
        """The corners' 1-sigma for a plate of their size (see ``corner_sigma_exponent``).

        In a rectified frame, the plate was imaged ``s`` times smaller than it is drawn
        (``s``: rectified px per raw px at its centre, :meth:`stretch`, above 1 towards the
        edges of a barrel-distorted frame), so its corners have the raw sigma of a plate
        ``width / s`` wide, stretched by ``s`` (computed when not given).  ``fit``: the
        alignment's own estimate (:func:`tracker.verify.fit_corner_sigma`); the larger of
        the two is stated."""
        if corners is None:
            return None
        s = self.stretch(corners) if s is None else s
        cfg = self.config
        quad = np.asarray(corners, np.float64)
        width = max(float(np.ptp(quad[:, 0])), 1.0)
        model = float(s * self.pose_config.pixel_sigma_px
                      * (cfg.corner_sigma_ref_px * s / width) ** cfg.corner_sigma_exponent)
        return model if fit is None else max(model, cfg.fit_sigma_scale * fit)

    def stated(self, track: Track, corners: Sequence[tuple[float, float]] | None, s: float
               ) -> float | None:
        """The 1-sigma stated for ``track``'s ``corners``: :meth:`sigma` with its alignment's
        fit, or, for a grey-aligned plate with ``grey_fit_sigma`` on, the fit alone (times
        ``fit_sigma_scale``): the size model was fitted on corners of the mixed plane."""
        fit = track.fit_sigma
        if corners is not None and fit is not None and self.config.grey_fit_sigma \
                and track.landmark_id in self.grey_plates:
            return self.config.fit_sigma_scale * fit
        return self.sigma(corners, s, fit)

    def modes(self, track: Track) -> tuple[float, ...] | None:
        """The outline modes stated for ``track``'s corners: on a lossy frame, a plate
        aligned on the mixed plane takes ``lossy_mixed_corner_mode_sigma_rel`` (a mode at 0
        the pose's); None on a lossless frame, for a grey-aligned plate, or when nothing is
        set (the pose's)."""
        own = self.config.lossy_mixed_corner_mode_sigma_rel
        if not self.lossy or not any(own) or track.landmark_id in self.grey_plates:
            return None
        return tuple(m or p for m, p in zip(own, self.pose_config.corner_mode_sigma_rel,
                                            strict=True))

    def floor(self, obs: Observation, tracks: Mapping[str, Track]) -> Observation:
        """``obs`` with its corner sigma raised for saturation (``saturated_sigma_gain``)
        and to what its track's corners have really missed by in recent fixes
        (``residual_sigma_fixes``); unchanged without corners."""
        track = None if obs.landmark_id is None else tracks.get(obs.landmark_id)
        if obs.corner_sigma_px is None or track is None:
            return obs
        sigma = obs.corner_sigma_px * (1.0 + self.config.saturated_sigma_gain * track.saturated)
        if track.residual_var is not None and self.config.residual_sigma_fixes > 0:
            sigma = max(sigma, float(np.sqrt(track.residual_var)))
        return obs if sigma == obs.corner_sigma_px else \
            dataclasses.replace(obs, corner_sigma_px=sigma)

    def alone(self, observations: Sequence[Observation], tracks: Mapping[str, Track]
              ) -> list[Observation]:
        """``observations``, where only one has corners, with that plate's corners less
        the steady error its track showed beside other plates (``corner_bias_fixes``);
        as given otherwise."""
        out = list(observations)
        need = self.config.corner_bias_fixes / 2
        with_corners = cornered(out)
        if need <= 0 or len(with_corners) != 1:
            return out
        obs = out[with_corners[0]]
        track = None if obs.landmark_id is None else tracks.get(obs.landmark_id)
        if track is None or track.bias_modes is None or track.bias_fixes < need \
                or not obs.all_corners or obs.corners_px is None:
            return out
        px = np.asarray(obs.corners_px, np.float64)
        moved = px - (outline_basis(px) @ track.bias_modes).reshape(-1, 2)
        out[with_corners[0]] = dataclasses.replace(
            obs, corners_px=tuple((float(u), float(v)) for u, v in moved))
        return out

    def learn(self, observations: Sequence[Observation], fix: PoseFix,
              tracks: Mapping[str, Track]) -> None:
        """Average each track's corner residuals against a fix from two or more plates'
        corners: mean square per coordinate times n / (n - 6), n the fix's corner
        coordinates, 6 the pose parameters fitted to them.  Not from a fix with an
        :meth:`unsettled` plate: its residuals are that outline's first guesses (stated
        loosely already), and a floor learnt from them outlived them -- a lone plate's
        corners stated at pixels for the rest of its track, so that its fixes followed the
        autopilot's attitude (docs/decisions.md, "The corners' residual floor is learnt
        from settled plates").  Each plate's residual along its outline's modes is averaged
        too, for when it is alone (:meth:`alone`)."""
        used = [(o.landmark_id, o) for o in observations if o.corners_px is not None
                and o.landmark_id in fix.landmark_ids and o.landmark_id in tracks]
        fixes = self.config.residual_sigma_fixes
        if len(used) < 2 or (fixes <= 0 and self.config.corner_bias_fixes <= 0) \
                or any(self.unsettled(tracks[lid]) for lid, _ in used if lid is not None):
            return
        n = 8 * len(used)
        by_id = {lm.landmark_id: lm for lm in self.landmarks}
        pos = np.asarray(fix.position_ned_m, np.float64)
        for lid, o in used:
            if lid is None:
                continue
            pts = self.camera.world_to_camera(landmark_corners_ned(by_id[lid]),
                                              pos, fix.attitude_rpy_rad)
            if not np.all(pts[:, 2] > 0):
                continue
            measured = np.asarray(o.corners_px, np.float64)
            resid = measured - self.camera.project_camera_points(pts)
            var = float(np.mean(resid**2)) * n / (n - POSE_PARAMETERS)
            track = tracks[lid]
            if fixes > 0:
                last = track.residual_var
                track.residual_var = var if last is None else last + (var - last) / fixes
            if o.all_corners:
                self._learn_bias(track, outline_basis(measured).T @ resid.ravel())

    def _learn_bias(self, track: Track, modes: FloatArray) -> None:
        """Average a plate's residual along its outline's modes over about
        ``corner_bias_fixes`` fixes."""
        span = self.config.corner_bias_fixes
        if span <= 0:
            return
        last = track.bias_modes
        track.bias_fixes += 1
        track.bias_modes = modes if last is None \
            else last + (modes - last) / min(span, track.bias_fixes)

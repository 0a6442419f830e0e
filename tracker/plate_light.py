"""A plate's light in a frame against its appearance image: each channel's gain, and the
template pixels that gain took past what the camera can hold (issue 25).

A frame's pixel at 255 says only that the scene was at least that bright there.  Where a
plate is lit brighter than its appearance image, the parts of it its gain takes past 255
are flat in the frame while the template keeps their detail; ECC's correlation is linear
in the levels, so those pixels pull the outline.  On the real-imagery world of seed 0,
after the light step to 125 % (real-03 lit at 2.1 times its image, 6-12 % of its pixels
clipped), its corners were aligned 0.4-0.5 px down; with the clipped part of the template
left out, its median corner error went 0.56 -> 0.33 px (docs/decisions.md, "An
over-exposed plate's clipped part is left out of its alignment").
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: A window pixel with a channel at this level or more is clipped.
CLIPPED_LEVEL = 250
#: ... and so, for the alignment, are its neighbours this far (px): JPEG and the warp's
#: interpolation spread a clipped area's edge, which then reads under ``CLIPPED_LEVEL``.
CLIPPED_SPREAD_PX = 2
#: A template pixel at or near a clipped one is left out when the plate's gain takes one
#: of its channels to this level or more: its appearance image's level times the plate's
#: mean over the image's mean in that channel.  Below it, a clipped neighbour is the edge
#: of a bright area, which holds the outline.
LOST_LEVEL = 255.0
#: ... and nothing is left out when more than this share of the template would be: the
#: alignment then lost sudden_light's plate (58 % at 255 under 160 % light), whose
#: corners are not used in the deployment past ``perception.max_corner_saturated`` (0.25).
MAX_LOST_SHARE = 0.25


def channel_ratio(crop: npt.NDArray[np.uint8], quad: FloatArray, own: FloatArray
                  ) -> FloatArray | None:
    """Each channel's mean inside the outline ``quad`` (crop px) over ``own`` (the
    appearance image's B, G, R means), each plus one; None for a grey crop or an outline
    of fewer than 16 px."""
    if crop.ndim != 3:
        return None
    mask = np.zeros(crop.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, np.round(quad).astype(np.int32), 255)
    if cv2.countNonZero(mask) < 16:
        return None
    seen = np.asarray(cv2.mean(crop, mask=mask)[:3], np.float64)
    return np.asarray((seen + 1.0) / (np.asarray(own, np.float64) + 1.0), np.float64)


def clipped(crop: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8] | None:
    """255 where a pixel of the window ``crop`` has a channel at ``CLIPPED_LEVEL`` or more;
    None when none has (or the crop is grey): nothing to leave out, at the cost of one
    ``inRange``."""
    if crop.ndim != 3:
        return None
    fine = cv2.inRange(crop, (0,) * 3, (CLIPPED_LEVEL - 1,) * 3)
    if cv2.countNonZero(fine) == fine.size:
        return None
    return np.asarray(cv2.bitwise_not(fine), np.uint8)


def unclipped(crop: npt.NDArray[np.uint8], flat: npt.NDArray[np.uint8], quad: FloatArray,
              warp: FloatArray, channels: Sequence[npt.NDArray[np.float32]], own: FloatArray
              ) -> npt.NDArray[np.uint8] | None:
    """The template pixels (``channels``: the appearance image's B, G, R at the template's
    size; ``warp``: template -> ``crop`` px) to align on in the window ``crop`` whose
    outline is ``quad`` and whose clipped pixels are ``flat`` (:func:`clipped`): 1 except
    where the frame is clipped, or within ``CLIPPED_SPREAD_PX`` of a clipped pixel, and the
    plate's gain (:func:`channel_ratio`) takes a channel to ``LOST_LEVEL`` or more.  None:
    all of them (none lost, or more than ``MAX_LOST_SHARE``)."""
    ratio = channel_ratio(crop, quad, own)
    if ratio is None:
        return None
    reach = np.ones((2 * CLIPPED_SPREAD_PX + 1,) * 2, np.uint8)
    height, width = channels[0].shape[:2]
    near = cv2.warpPerspective(cv2.dilate(flat, reach),
                               np.asarray(warp, np.float64), (width, height),
                               flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP)
    lost = near > 0
    over = np.zeros(lost.shape, bool)
    for plane, gain in zip(channels, ratio, strict=True):
        over |= plane >= LOST_LEVEL / gain
    lost &= over
    count = int(lost.sum())
    if count == 0 or count > MAX_LOST_SHARE * lost.size:
        return None
    return np.asarray(~lost, np.uint8)

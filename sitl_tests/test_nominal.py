"""Nominal flights: the survey the companion is built for, with nothing going wrong."""

from __future__ import annotations

import math

import numpy as np

from companion.settings import Settings
from sitl_tests.harness import Flight, max_gap_s

SURVEY_S = 12.0


async def test_nominal_survey_flight(settings: Settings) -> None:
    """Survey past the street's landmarks: the autopilot fuses steady fixes close to truth.

    Proves: fixes reach the autopilot at a useful rate once the landmarks are in view, the
    autopilot accepts >= 90 % of them, their position is within 0.5 m RMSE of truth, every
    covariance is finite, positive and honest (errors mostly inside 3 sigma), no value is
    NaN, and every fix is logged in the flight log.
    """
    flight = await Flight("survey", SURVEY_S, settings).run()
    fake = flight.fake
    arrivals = fake.arrivals
    assert flight.frames, "the companion processed no frame"
    assert arrivals, "the autopilot received no fix"
    accepted = sum(a.accepted for a in arrivals) / len(arrivals)
    assert accepted >= 0.9, fake.summary()["vision_reasons"]
    # steady: from the first fix to the end, >= 5 Hz (camera 15 Hz) and no gap over 1 s
    times = fake.accepted_times()
    rate_hz = len(times) / (flight.seconds - times[0])
    assert rate_hz >= 5.0 and max_gap_s(times, times[0], flight.seconds) < 1.0, rate_hz
    fixes = flight.fixes()
    assert flight.rmse_m() < 0.5, f"RMSE {flight.rmse_m():.3f} m"
    for f in fixes:
        assert f.fix_ned_m is not None and f.fix_sigma_m is not None
        assert all(math.isfinite(v) for v in f.fix_ned_m)
        assert all(math.isfinite(s) and 0.0 < s < 5.0 for s in f.fix_sigma_m), f.fix_sigma_m
    # the covariance is not hiding the error: 3-sigma per axis holds for >= 90 % of fixes
    inside = [all(abs(a - b) <= 3 * max(s, 0.05) for a, b, s in
                  zip(f.fix_ned_m, f.truth_ned_m, f.fix_sigma_m, strict=True))  # type: ignore[arg-type]
              for f in fixes]
    assert np.mean(inside) >= 0.9, f"{np.mean(inside):.2f} of fixes inside 3 sigma"
    assert all(math.isfinite(a.position_ned_m[0]) for a in arrivals)
    log = flight.flight_log()
    assert flight.app is not None
    assert log.kinds["fix"] == flight.app.counters.fixes_sent == len(arrivals)
    print(f"survey: {len(arrivals)} fixes, {accepted:.1%} accepted, "
          f"RMSE {flight.rmse_m():.3f} m, {len(flight.frames)} frames")

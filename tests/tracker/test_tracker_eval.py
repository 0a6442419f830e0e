"""Sequence loading and the ``companion eval`` command end to end on a tiny OTB folder."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from companion.cli import eval_cmd
from companion.errors import InputError
from companion.evaluation.sequences import load_sequence
from companion.evaluation.synthetic import SynthSpec, write_otb
from companion.settings import Settings


@pytest.fixture(scope="module")
def otb_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("otb") / "Sign"
    write_otb(SynthSpec(frames=12, width_px=320, height_px=240, illumination=False), folder)
    return folder


def test_otb_truth_is_read_zero_based(otb_folder: Path) -> None:
    seq = load_sequence(otb_folder)
    assert len(seq.frames) == 12 and seq.truth.shape == (12, 4)
    first = (otb_folder / "groundtruth_rect.txt").read_text().splitlines()[0].split(",")
    assert seq.truth[0, 0] == float(first[0]) - 1


def test_not_a_sequence_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="expected an OTB folder"):
        load_sequence(tmp_path)


def test_eval_writes_table_json_and_report(
    otb_folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = argparse.ArgumentParser()
    eval_cmd.register(parser.add_subparsers())
    args = parser.parse_args(
        [
            "eval",
            str(otb_folder),
            "--trackers",
            "adaptive,meanshift",
            "--json",
            str(tmp_path / "r.json"),
            "--report",
            str(tmp_path / "rep"),
        ]
    )
    assert eval_cmd.run(args, Settings()) == 0
    out = capsys.readouterr().out
    assert "| Sign | adaptive |" in out and "| Sign | meanshift |" in out
    rows = json.loads((tmp_path / "r.json").read_text())
    assert {r["tracker"] for r in rows} == {"adaptive", "meanshift"}
    adaptive = next(r for r in rows if r["tracker"] == "adaptive")
    assert adaptive["frames"] == 11 and adaptive["particles"] == 20
    assert adaptive["success_auc"] > 0.5 and np.isfinite(adaptive["updates_per_s"])
    report = (tmp_path / "rep" / "report.md").read_text()
    for png in (
        "Sign_centre_error.png",
        "Sign_success.png",
        "Sign_precision.png",
        "Sign_likelihood.png",
    ):
        assert png in report and (tmp_path / "rep" / png).stat().st_size > 1000


def test_unknown_tracker_is_an_input_error(otb_folder: Path) -> None:
    parser = argparse.ArgumentParser()
    eval_cmd.register(parser.add_subparsers())
    args = parser.parse_args(["eval", str(otb_folder), "--trackers", "adaptive,kcf"])
    with pytest.raises(InputError, match="--trackers"):
        eval_cmd.run(args, Settings())


@pytest.fixture(scope="module")
def stream_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short recorded stream written by the simulator (companion synth)."""
    import dataclasses

    from companion.sim.scenario import load_scenario
    from companion.sim.simulator import Simulator
    from companion.sim.synth import synth_stream

    scenario = dataclasses.replace(load_scenario("hover"), seconds=0.3, fps=20.0)
    out = tmp_path_factory.mktemp("stream") / "hover"
    synth_stream(Simulator(scenario), out, image_format="jpg")
    return out


def test_recorded_stream_truth_follows_one_landmark(stream_folder: Path) -> None:
    seq = load_sequence(stream_folder)
    assert len(seq.frames) == 6 and seq.truth.shape == (6, 4)
    landmark = seq.name.split(":")[1]
    rows = [
        line.split(",") for line in (stream_folder / "truth_boxes.csv").read_text().splitlines()[1:]
    ]
    first = next(r for r in rows if r[0] == "0" and r[1] == landmark)
    assert np.allclose(seq.truth[0], [float(v) for v in first[2:6]])
    with pytest.raises(InputError, match="no landmark 'nope'"):
        load_sequence(stream_folder, "nope")

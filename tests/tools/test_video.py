"""parallax-render RUN --video OUT and the video panel in TensorBoard, on shrunken runs."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from PIL import Image

from parallax.tools import render, video
from tests.conftest import IMAGES, TINY, train_tiny_run

#: tab:blue and tab:orange, the colours of the pan and of α* in the panel's plots.
BLUE, ORANGE = (31, 119, 180), (255, 127, 14)
#: Iterations of one shrunken presentation: two lateral positions of four iterations.
ITERATIONS = 2 * 4


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    return train_tiny_run(tmp_path_factory.mktemp("run") / "run", [IMAGES])


def near(region: np.ndarray, colour: tuple[int, int, int], tolerance: int = 60) -> int:
    """Pixels of ``region`` (RGB) within ``tolerance`` of ``colour`` in every channel."""
    return int((np.abs(region.astype(int) - colour) <= tolerance).all(axis=-1).sum())


def panel_regions(run, width: int) -> dict[str, tuple[int, int, int, int]]:
    """Where the panel of a ``width`` pixels wide video draws its four parts."""
    from parallax.panel import PanelDrawer

    watched = next(iter(video.watched_presentations(run, [3.0], say=lambda *_: None)))
    drawer = PanelDrawer(watched, width)
    try:
        drawer.draw(len(watched.samples) - 1)
        return drawer.regions()
    finally:
        drawer.close()


def assert_panel_drawn(frame: np.ndarray, regions: dict) -> None:
    """Every part shows something: the two cameras' pictures vary, the plots hold the pan
    (blue) and α* (orange)."""
    crop = {k: frame[top:bottom, left:right] for k, (left, top, right, bottom) in regions.items()}
    for camera in ("side", "eye"):
        assert crop[camera].size and crop[camera].std() > 10, f"{camera} view is blank"
    for plot in ("pan", "s"):
        assert near(crop[plot], BLUE) > 10, f"no pan in the {plot} plot"
        assert near(crop[plot], ORANGE) > 10, f"no α* in the {plot} plot"


def test_mp4_has_every_iteration_and_the_held_end(tiny_run, tmp_path, capsys) -> None:
    out = tmp_path / "robot.mp4"
    result = video.write_video(tiny_run, out, distances=[3.0, 10.0], fps=10, hold_s=1.0)
    # each presentation: its iterations, the last one held for a second (10 frames)
    per_presentation = ITERATIONS - 1 + 10
    assert result["frames"] == 2 * per_presentation
    capture = cv2.VideoCapture(str(out))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
    assert len(frames) == 2 * per_presentation
    assert frames[0].shape == (540, 960, 3)
    regions = panel_regions(tiny_run, 960)
    # the end of the first presentation (its plots full) and the end of the video
    for index in (ITERATIONS - 1, len(frames) - 1):
        assert_panel_drawn(frames[index], regions)
    text = capsys.readouterr().out
    assert "greedy, on heldout photograph 0" in text and str(out) in text
    assert not list(tmp_path.glob(".*partial*"))


def test_gif_frames_and_size(tiny_run, tmp_path) -> None:
    out = tmp_path / "robot.gif"
    video.write_video(tiny_run, out, distances=[4.0], width=480, every=3, progress=False)
    gif = Image.open(out)
    # every third iteration and each trial's last: iterations 0, 3 (a trial's last) and 6, 7
    assert gif.n_frames == 4
    assert gif.size == (480, 270)
    gif.seek(gif.n_frames - 1)
    assert_panel_drawn(np.asarray(gif.convert("RGB")), panel_regions(tiny_run, 480))


@pytest.mark.parametrize(
    "experiment",
    [
        "continuous_multi_5_20_weighted",
        "planned_multi_5_20_weighted",
        "embodied_multi_5_20_weighted",
    ],
)
def test_every_kind_of_robot(experiment, tmp_path) -> None:
    run = train_tiny_run(tmp_path / "run", [f"experiment={experiment}"])
    shown = list(video.watched_presentations(run, [3.0], every=4, say=lambda *_: None))[0]
    iterations = [s for s in shown.samples if s.walked_m is None]
    walked = [s for s in shown.samples if s.walked_m is not None]
    assert shown.reading is not None  # the distance learner (or the planner) is ready
    if experiment.startswith("continuous"):
        # one trial in which the body sweeps 0 … 10 cm, 2 mm an iteration
        assert len(iterations) == 51 and iterations[-1].lateral_m == pytest.approx(0.1)
        assert shown.continuous and not np.isnan(shown.pans).any()
    elif experiment.startswith("planned"):
        assert "planned route" in shown.title
        assert len(iterations) == 4 * np.isfinite(shown.pans).sum()
    else:  # the body walks from l0 until its hand touches the panel, 3 m ahead of the eye
        assert len(iterations) == ITERATIONS and len(walked) > 2
        # the hand, ahead of the eye, touches 2.98 m on: the walk's last step of 2 cm ends there
        assert 2.98 <= walked[-1].walked_m <= 3.0 + 1e-6
        assert all(s.pictured for s in walked)
    out = tmp_path / "robot.gif"
    video.write_video(run, out, distances=[3.0], width=480, every=4, progress=False)
    assert Image.open(out).n_frames == sum(s.pictured for s in shown.samples)


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--video", "{tmp}/robot.avi"], "must end in .mp4 or .gif"),
        (["--video", "{tmp}/no/such/file/robot.mp4"], "lies inside"),
        (["--video", "{tmp}/robot.mp4", "--texture", "99"], "--texture must be between 0 and"),
        (["--video", "{tmp}/robot.mp4", "--every", "0"], "--every must be at least 1"),
        (["--video", "{tmp}/robot.mp4", "--distance", "-1"], "--distance must be a positive"),
    ],
)
def test_bad_input_is_one_line_and_nothing_written(
    tiny_run, tmp_path, capsys, arguments, message
) -> None:
    (tmp_path / "no").write_text("a file, not a folder")
    argv = [str(tiny_run)] + [a.format(tmp=tmp_path) for a in arguments]
    assert render.main(argv) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1  # one line: what is wrong, and nothing else
    assert error[0].startswith("parallax-render: error: --") and message in error[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["no"]


def test_missing_run_is_one_line(tmp_path, capsys) -> None:
    assert render.main([str(tmp_path / "nothing"), "--video", str(tmp_path / "robot.mp4")]) == 2
    assert "is not a parallax run directory" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_tensorboard_panel_every_image_every(tiny_run) -> None:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(tiny_run / "tb"), size_guidance={"images": 0})
    events.Reload()
    images = events.Images("world/presentation")
    lines = [json.loads(line) for line in (tiny_run / "metrics.jsonl").read_text().splitlines()]
    # train.image_every=3 of 6 presentations: the 3rd and the 6th, at their iteration counts
    every = int(IMAGES.split("=")[1])
    kept = [line["steps"] for line in lines if line["presentation"] % every == 0]
    assert [image.step for image in images] == kept == [lines[2]["steps"], lines[5]["steps"]]
    # without moviepy: four of its frames, 640 × 360 each, two to a row
    picture = cv2.imdecode(np.frombuffer(images[-1].encoded_image_string, np.uint8), 1)
    assert picture.shape == (720, 1280, 3)
    assert picture[:360, :640].std() > 10 and picture[360:, 640:].std() > 10


def test_tensorboard_panel_is_a_video_with_moviepy(tmp_path, monkeypatch) -> None:
    from parallax import run_log
    from parallax.config import compose

    written = {}
    monkeypatch.setattr(run_log, "can_write_video", lambda: True)
    frames = [np.full((360, 640, 3), k, np.uint8) for k in range(5)]
    with run_log.RunLog(tmp_path, compose(TINY), 0, 0, False) as log:
        monkeypatch.setattr(
            log.writer, "add_video", lambda tag, v, step, fps: written.update(tag=tag, v=v)
        )
        log.panel(frames, 7)
    assert written["tag"] == "world/presentation"
    assert written["v"].shape == (1, 5, 3, 360, 640)  # (N, T, C, H, W), as add_video takes it
    assert written["v"][0, 4, 0, 0, 0] == 4


def test_watching_changes_nothing_the_run_computes(tiny_run, tmp_path) -> None:
    """train.image_every does not change a run's results (it is result-neutral): the same run
    with no presentation watched writes the same metrics.jsonl."""
    unwatched = train_tiny_run(tmp_path / "run", ["train.image_every=100"])
    assert (unwatched / "metrics.jsonl").read_text() == (tiny_run / "metrics.jsonl").read_text()

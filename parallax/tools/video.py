"""`parallax-render RUN --video OUT`: a trained robot at work, as a video (paper §3.2, §3.5, §4.1).

One presentation per distance asked for, frozen and greedy as ``parallax-eval`` runs them, on a
held-out photograph (:func:`parallax.tools.evaluate.frozen_experiment`): the robot sweeps L
(pick and place, or the continuous sweep of env.motion=continuous), or goes where its planner
sends it (movement.route=planned, §7); a robot that learnt from its own walks
(distance.targets=odometry, §7) then walks to the panel. Every frame is the panel of
:mod:`parallax.panel`: side camera, left eye with its fovea and periphery, the pan against α*,
and at the end the distance read against the true one (for a walking robot, the slip-free walk
to the panel in its own metres).

OUT ends in ``.mp4`` (OpenCV's VideoWriter) or ``.gif`` (Pillow, which matplotlib installs).
Bad input ends the command with one line, and nothing written.
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from parallax import checkpoint, readouts
from parallax.config import load_run_config
from parallax.envs.settings import SPLITS
from parallax.panel import PANEL_COLOURS, Watched, frame_size, panel_frames, watched
from parallax.routes import SWEEP, planned_route
from parallax.tools.evaluate import frozen_experiment, read_checkpoint
from parallax.watch import Watch
from parallax.writable import file_problem

#: The video formats, by OUT's extension.
FORMATS = (".mp4", ".gif")


def check_video_options(
    run_dir: str | Path | None,
    out: str | Path,
    distances: Sequence[float],
    every: int,
    fps: float,
    width: int,
) -> Path:
    """OUT as a path, once everything asked for can be done; else a ValueError naming it."""
    out = Path(out)
    if run_dir is None:
        raise ValueError("--video needs a run directory: parallax-render RUN --video OUT")
    if out.suffix.lower() not in FORMATS:
        raise ValueError(f"--video {out}: the file must end in {' or '.join(FORMATS)}")
    problem = file_problem(out)
    if problem:
        raise ValueError(f"--video {out} {problem}")
    for d in distances:
        if not (math.isfinite(d) and d > 0):
            raise ValueError(f"--distance must be a positive number of metres, got {d!r}")
    if every < 1:
        raise ValueError(f"--every must be at least 1 iteration, got {every}")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"--fps must be a positive number, got {fps!r}")
    if width < 320:
        raise ValueError(f"--width must be at least 320 pixels, got {width}")
    return out


def watched_presentations(
    run_dir: str | Path,
    distances: Sequence[float] = (3.0,),
    texture_index: int = 0,
    checkpoint_name: str = checkpoint.CHECKPOINT_NAME,
    perturbation: str = "auto",
    split: str = "heldout",
    every: int = 1,
    device: str | None = None,
    say=print,
    progress: bool = False,
) -> Iterable[Watched]:
    """One frozen, greedy presentation of the run's checkpoint per distance, on held-out
    photograph ``texture_index``, each watched as the panel draws it; ``say`` gets the header,
    and with ``progress`` a bar follows each presentation's iterations."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    state = read_checkpoint(run_dir, cfg, checkpoint_name, device)
    trained = int(cfg.env.robots)
    walking = cfg.distance.targets == "odometry"
    if not walking:  # one robot is watched; the others would only slow it down
        cfg.env.robots = 1
    exp, perturbed, _ = frozen_experiment(
        cfg, state, run_dir / checkpoint_name, split, perturbation, "auto", trained
    )
    try:
        photos = exp.envs[0].task.num_textures
        if not 0 <= texture_index < photos:
            raise ValueError(f"--texture must be between 0 and {photos - 1}, got {texture_index}")
        name = exp.envs[0].physics.stimuli.names[texture_index]
        readout = readouts.of_run(cfg)
        planner = exp.planner if exp.planner is not None and exp.planner.is_ready else None
        route = SWEEP if planner is None else planned_route(planner, readout)
        truths = functools.partial(exp.distance.target_source.truths, bodies=exp.parts)
        say(
            f"[parallax-render] {run_dir}/{checkpoint_name} (presentation "
            f"{int(state['presentation'])}{', perturbed' if perturbed else ''}), greedy, on "
            f"{split} photograph {texture_index} ({name}) at "
            + ", ".join(f"{d:g} m" for d in distances)
        )
        for d in distances:
            for env in exp.envs:
                env.task.set_next_stimulus(texture_index=texture_index, distance=float(d))
            task = exp.envs[0].task  # a planned route may stop before the end of L
            bar = tqdm(
                total=task.trials * task.trial_length, desc=f"{d:g} m", unit="iteration",
                disable=not progress, leave=False,
            )  # fmt: skip
            watch = Watch(exp.envs[0], every=every, on_sample=lambda _, bar=bar: bar.update())
            with bar:
                pres = exp.run_presentation(
                    learn=False, greedy=True, route=route, watch=watch.around
                )
            how = ", planned route" if pres.route is not None else ""
            how += ", walks to the panel" if exp.walks else ""
            photo = name.split("[")[0]  # the photograph, without where it was cut from
            run = run_dir.resolve().name  # e.g. the experiment and seed
            run = run if len(run) <= 40 else run[:39] + "…"
            title = f"{run}{how}: panel at {d:g} m, {split} photograph {photo}"
            yield watched(watch, pres, exp.parts, readout, title, truths, walk=exp.walks)
    finally:
        exp.close()


class _Sink:
    """Frames into OUT through a temporary file beside it, renamed only once all is written."""

    def __init__(self, out: Path, fps: float, size: tuple[int, int]) -> None:
        self.out, self.fps, self.size = out, fps, size
        self.temporary = out.with_name(f".{out.stem}.partial{out.suffix}")
        self.gif = _Gif() if out.suffix.lower() == ".gif" else None
        self.writer: cv2.VideoWriter | None = None  # opened with the first frame
        self.frames = 0

    def _open(self) -> cv2.VideoWriter:
        self.out.parent.mkdir(parents=True, exist_ok=True)
        fourcc = cv2.VideoWriter_fourcc(*"mp4v")
        writer = cv2.VideoWriter(str(self.temporary), fourcc, self.fps, self.size)
        if not writer.isOpened():
            raise OSError(f"OpenCV cannot write an .mp4 video at {self.temporary}")
        return writer

    def add(self, frame: np.ndarray, seconds: float | None = None) -> None:
        """One frame, shown for one frame's time or ``seconds``; :attr:`frames` counts the
        frames the file holds."""
        if self.gif is not None:
            self.gif.add(frame, int(round(1000 * (seconds or 1 / self.fps))))
            self.frames += 1
            return
        if self.writer is None:
            self.writer = self._open()
        repeats = 1 if seconds is None else max(1, round(seconds * self.fps))
        self.frames += repeats  # a frame held is written again: the file counts each one
        for _ in range(repeats):
            self.writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))

    def close(self) -> Path:
        if self.gif is not None:
            self.out.parent.mkdir(parents=True, exist_ok=True)
            self.gif.save(self.temporary)
        else:
            self.writer.release()
        os.replace(self.temporary, self.out)
        return self.out

    def abort(self) -> None:
        if self.writer is not None:
            self.writer.release()
        self.temporary.unlink(missing_ok=True)


class _Gif:
    """GIF frames on one palette, each pixel that did not change left transparent (so showing
    the frame before): the cameras' pictures change little from frame to frame, and runs of
    transparent pixels compress to almost nothing."""

    #: The palette entry of "as in the frame before".
    UNCHANGED = 255

    def __init__(self) -> None:
        self.palette = None  # a Pillow palette image, made from the first frame
        self.previous: np.ndarray | None = None  # the last frame's palette indices
        self.images: list = []
        self.durations: list[int] = []

    def add(self, frame: np.ndarray, milliseconds: int) -> None:
        from PIL import Image

        image = Image.fromarray(frame)
        if self.palette is None:
            # the panel's own colours exactly (the plots, the windows), the pictures' the rest
            keys = list(PANEL_COLOURS)
            pictures = image.quantize(
                colors=self.UNCHANGED - len(keys), method=Image.Quantize.MEDIANCUT
            ).getpalette()[: 3 * (self.UNCHANGED - len(keys))]
            entries = pictures + [v for c in keys for v in c]
            entries += [0] * (768 - len(entries))
            self.palette = Image.new("P", (1, 1))
            self.palette.putpalette(entries)
        # no dithering: flat colours stay flat, and an unchanged pixel keeps its index
        indices = np.asarray(image.quantize(palette=self.palette, dither=Image.Dither.NONE))
        shown = indices.copy()
        if self.previous is not None:
            shown[indices == self.previous] = self.UNCHANGED
        self.previous = indices
        coded = Image.fromarray(shown, mode="P")
        coded.putpalette(self.palette.getpalette())
        self.images.append(coded)
        self.durations.append(milliseconds)

    def save(self, path: Path) -> None:
        first, *rest = self.images
        first.save(
            path,
            format="GIF",
            save_all=True,
            append_images=rest,
            duration=self.durations,
            loop=0,
            transparency=self.UNCHANGED,
            disposal=1,  # each frame stays, under the next one's transparent pixels
            optimize=False,  # keeps the palette, and so the meaning of each index
        )


def write_video(
    run_dir: str | Path,
    out: str | Path,
    distances: Sequence[float] = (3.0,),
    texture_index: int = 0,
    checkpoint_name: str = checkpoint.CHECKPOINT_NAME,
    perturbation: str = "auto",
    split: str = "heldout",
    every: int = 1,
    fps: float = 30.0,
    width: int = 960,
    hold_s: float = 1.5,
    device: str | None = None,
    progress: bool = True,
) -> dict:
    """The video of :func:`watched_presentations` into ``out``; each presentation's last frame
    (its distance read) held for ``hold_s`` seconds. Returns the file, its frames, their size."""
    out = check_video_options(run_dir, out, distances, every, fps, width)
    say = print if progress else (lambda *_: None)
    sink = _Sink(out, fps, frame_size(width))
    try:
        for watched in watched_presentations(
            run_dir, distances, texture_index, checkpoint_name, perturbation, split, every,
            device, lambda header: say(f"{header} → {out}"), progress,
        ):  # fmt: skip
            pictured = sum(s.pictured for s in watched.samples)
            frames = panel_frames(watched, width)
            bar = tqdm(
                frames, total=pictured, desc="drawing", unit="frame", disable=not progress,
                leave=False,
            )  # fmt: skip
            last = None
            for frame in bar:
                if last is not None:
                    sink.add(last)
                last = frame
            sink.add(last, seconds=hold_s)
        path = sink.close()
    except BaseException:
        sink.abort()
        raise
    say(f"[parallax-render] wrote {path} ({sink.frames} frames, {path.stat().st_size} bytes)")
    return {"path": path, "frames": sink.frames, "size": frame_size(width)}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """parallax-render's options for --video (RUN and --distance are its own)."""
    group = parser.add_argument_group("video of a trained run (parallax-render RUN --video OUT)")
    group.add_argument("--video", default=None, metavar="OUT", help="the video: OUT.mp4 or OUT.gif")
    group.add_argument(
        "--checkpoint",
        default=checkpoint.CHECKPOINT_NAME,
        help=f"checkpoint file in the run dir (default {checkpoint.CHECKPOINT_NAME}; "
        f"{checkpoint.BEFORE_PERTURBATION_NAME}: before §5's perturbation)",
    )
    group.add_argument(
        "--perturbation",
        choices=["auto", "on", "off"],
        default="auto",
        help="§5's perturbation; auto: as at the end of training (default)",
    )
    group.add_argument(
        "--split",
        choices=SPLITS,
        default="heldout",
        help="photographs never seen in training (heldout, default) or those the eye learnt on",
    )
    group.add_argument(
        "--every",
        type=int,
        default=1,
        help="a frame every this many iterations, and at the end of every trial (default 1)",
    )
    group.add_argument("--fps", type=float, default=30.0, help="frames per second (default 30)")
    group.add_argument("--width", type=int, default=960, help="frame width in pixels (default 960)")
    group.add_argument(
        "--device", default=None, help="cpu or cuda (default: the device the run was trained on)"
    )


def main(args: argparse.Namespace) -> int:
    """parallax-render --video: one clear line and exit 2 for bad input, nothing written."""
    try:
        check_video_options(
            args.run_dir, args.video, args.distance, args.every, args.fps, args.width
        )
        write_video(
            args.run_dir,
            args.video,
            distances=args.distance,
            texture_index=0 if args.texture is None else args.texture,
            checkpoint_name=args.checkpoint,
            perturbation=args.perturbation,
            split=args.split,
            every=args.every,
            fps=args.fps,
            width=args.width,
            device=args.device,
        )
    except (FileNotFoundError, ValueError) as error:
        print(f"parallax-render: error: {error}", file=sys.stderr)
        return 2
    return 0

"""The video panel: one robot's presentation as frames (paper §3.2, Fig. 3; §3.5; §4.1).

Each frame shows, at one iteration of a presentation watched by :class:`parallax.watch.Watch`:

- the side camera, the body at its lateral position (during an embodied robot's walk, on its
  way to the panel);
- the left eye's image I(t) with the centre windows of the coder's scales drawn on it: the
  fovea (the fine scale) and the periphery (the coarse one), the parts of the image it encodes;
- the pan α so far against the target pan α*, iteration by iteration, and s, the pan the
  distance learner reads at every position visited so far, against α* there;
- at the end, the distance the robot reads against the true one.

``parallax-render RUN --video OUT`` writes the frames as a video; the trainer puts them into
TensorBoard every train.image_every presentations. Drawn with matplotlib's Agg canvas (no
pyplot: the user's backend and settings stay as they are), one figure reused for every frame,
and OpenCV for the cameras' pictures.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from parallax.parts import Parts
from parallax.presentation import Presentation
from parallax.readouts import PanReadout
from parallax.watch import Sample, Watch, read_distance, walk_samples

#: What each scale's window is on the retina, and its colour.
WINDOW_NAMES = {"fine": "fovea", "coarse": "periphery"}
WINDOW_COLOURS = {"fine": (255, 59, 48), "coarse": (0, 200, 255)}
#: Colours the panel draws with (RGB): a GIF's palette keeps them exact.
PANEL_COLOURS = [
    (255, 255, 255), (0, 0, 0), (31, 119, 180), (255, 127, 14), *WINDOW_COLOURS.values(),
]  # fmt: skip
#: Frame size (pixels) is width × width·ASPECT, both even (what video encoders want).
ASPECT = 9 / 16


@dataclass
class Watched:
    """What the panel of one presentation draws."""

    samples: list[Sample]  # robot 0's iterations, in order (then its walk, if any)
    lateral_positions: list[float]  # L (m)
    pans: np.ndarray  # (r,) s: the pan read at each l_p (NaN: not visited)
    targets: np.ndarray  # (r,) α* at each l_p (NaN: not visited)
    windows: dict[str, int]  # the coder's centre window per scale (pixels)
    title: str  # what is shown: run, distance, photograph
    reading: tuple[float, float] | None = None  # (distance read, truth) in m; None: not yet
    continuous: bool = False  # the body sweeps L in one trial (env.motion=continuous)
    readout: str = "last"  # which pan of a trial s holds (train.distance_readout)


def watched(
    watch: Watch,
    pres: Presentation,
    parts: Parts,
    readout: type[PanReadout],
    title: str,
    truths: Callable | None = None,
    walk: bool = False,
) -> Watched:
    """What the panel draws of robot 0's presentation ``pres``, watched by ``watch``: s as
    ``readout`` reads it, the distance read (:func:`parallax.watch.read_distance`, against
    ``truths``) and, with ``walk``, the body's walk to the panel."""
    pans = pres.read(readout)[0]
    return Watched(
        samples=watch.samples + (walk_samples(watch) if walk else []),
        lateral_positions=list(pres.lateral_positions),
        pans=np.where(np.isnan(pres.targets[0]), np.nan, pans),
        targets=pres.targets[0],
        windows={scale: parts.coder.coders[scale].spec.window for scale in parts.coder.scales},
        title=title,
        reading=read_distance(parts, pres, readout, truths),
        continuous=parts.worlds[0].task.continuous,
        readout=readout.name,
    )


def frame_size(width: int) -> tuple[int, int]:
    """(width, height) of a frame ``width`` pixels wide, both even."""
    width = max(320, int(width) // 2 * 2)
    return width, int(round(width * ASPECT / 2)) * 2


def revealed(watched: Watched, index: int) -> np.ndarray:
    """Which positions of L robot 0 had finished (s read there) by sample ``index``."""
    done = np.zeros(len(watched.lateral_positions), dtype=bool)
    lateral = np.asarray(watched.lateral_positions)
    for sample in watched.samples[: index + 1]:
        if sample.walked_m is not None:
            continue
        if watched.continuous:
            done |= lateral <= sample.lateral_m + 1e-9
        elif sample.last_of_trial:
            done |= np.isclose(lateral, sample.lateral_m, atol=1e-9)
    return done & ~np.isnan(watched.pans)


class PanelDrawer:
    """One figure for every frame of a :class:`Watched` presentation. What stays (axes, ticks,
    labels) is drawn once; each frame restores it, draws what changes (curves, points, titles)
    and pastes the two cameras' pictures into their boxes with OpenCV, the fovea and the
    periphery on the eye's: many times faster than redrawing the figure."""

    def __init__(self, watched: Watched, width: int = 960) -> None:
        self.watched = watched
        self.size = frame_size(width)
        dpi = 100
        self.font = 9 * self.size[0] / 960  # fonts keep their share of the frame
        self.figure = Figure(figsize=(self.size[0] / dpi, self.size[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        grid = self.figure.add_gridspec(
            2, 2, height_ratios=(1.7, 1), width_ratios=(2, 1), left=0.06, right=0.985,
            top=0.9, bottom=0.09, hspace=0.32, wspace=0.14,
        )  # fmt: skip
        self.side_axes = self.figure.add_subplot(grid[0, 0])
        self.eye_axes = self.figure.add_subplot(grid[0, 1])
        self.pan_axes = self.figure.add_subplot(grid[1, 0])
        self.s_axes = self.figure.add_subplot(grid[1, 1])
        self.figure.suptitle(watched.title, fontsize=1.2 * self.font)
        first = next(s for s in watched.samples if s.pictured)
        self.image_size = first.eye.shape[0]
        for axes, picture in ((self.side_axes, first.side), (self.eye_axes, first.eye)):
            axes.set_xticks([])
            axes.set_yticks([])
            axes.set_box_aspect(picture.shape[0] / picture.shape[1])
        self.eye_axes.set_xlabel(
            ", ".join(
                f"{WINDOW_NAMES.get(scale, scale)} ({window} px)"
                for scale, window in watched.windows.items()
            ),
            fontsize=self.font,
        )
        self.side_title = self.side_axes.set_title(" ", fontsize=self.font)
        self.eye_title = self.eye_axes.set_title(" ", fontsize=self.font)
        self._pan_plot()
        self._s_plot()
        self.changing = [
            self.side_title, self.eye_title, self.target_line, self.pan_line, self.s_targets,
            self.s_pans, self.s_title,
        ]  # fmt: skip
        for artist in self.changing:
            artist.set_animated(True)
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)
        self.boxes = self.regions()

    def _pan_plot(self) -> None:
        steps = [s for s in self.watched.samples if s.walked_m is None]
        values = [v for s in steps for v in (s.pan_deg, s.target_deg)]
        low, high = min(values + [0.0]), max(values + [0.0])
        margin = 0.08 * (high - low) + 0.05
        axes = self.pan_axes
        axes.set_xlim(0, max(len(steps) - 1, 1))
        axes.set_ylim(low - margin, high + margin)
        axes.set_xlabel("iteration", fontsize=self.font)
        axes.set_ylabel("pan (deg)", fontsize=self.font)
        axes.tick_params(labelsize=self.font)
        # an action holds until the next iteration
        style = {"drawstyle": "steps-post", "lw": 1.8}
        (self.target_line,) = axes.plot([], [], "--", color="tab:orange", label="α*", **style)
        (self.pan_line,) = axes.plot([], [], "-", color="tab:blue", label="pan α", **style)
        axes.legend(loc="upper left", fontsize=self.font, ncol=2)
        axes.grid(alpha=0.3)

    def _s_plot(self) -> None:
        axes, watched = self.s_axes, self.watched
        lateral_cm = 100 * np.asarray(watched.lateral_positions)
        values = np.concatenate([watched.pans, watched.targets, [0.0]])
        values = values[np.isfinite(values)]
        margin = 0.08 * (values.max() - values.min()) + 0.05
        axes.set_xlim(min(0.0, lateral_cm.min()) - 1, lateral_cm.max() + 1)
        axes.set_ylim(values.min() - margin, values.max() + margin)
        axes.set_xlabel("lateral position l (cm)", fontsize=self.font)
        axes.tick_params(labelsize=self.font)
        # at the end, the distance read in its place
        self.s_title = axes.set_title(" ", fontsize=self.font)
        size = (0.67 * self.font) ** 2
        self.s_targets = axes.scatter(
            [], [], s=size, lw=1.8, facecolors="none", edgecolors="tab:orange", label="α*"
        )
        self.s_pans = axes.scatter([], [], s=0.5 * size, color="tab:blue", label="s")
        axes.legend(loc="lower right", fontsize=self.font, ncol=2)
        axes.grid(alpha=0.3)

    def draw(self, index: int) -> np.ndarray:
        """The frame of sample ``index`` (which must be pictured): (H, W, 3) uint8."""
        watched, sample = self.watched, self.watched.samples[index]
        steps = [s for s in watched.samples[: index + 1] if s.walked_m is None]
        where = f"l = {100 * sample.lateral_m:.1f} cm"
        if sample.walked_m is not None:
            where = f"walking to the panel: {sample.walked_m:.2f} m"
        self.side_title.set_text(f"side camera, {where}")
        self.eye_title.set_text(
            f"left eye: α = {sample.pan_deg:.2f}°, α* = {sample.target_deg:.2f}°"
        )
        x = np.arange(len(steps))
        self.pan_line.set_data(x, [s.pan_deg for s in steps])
        self.target_line.set_data(x, [s.target_deg for s in steps])
        done = revealed(watched, index)
        lateral_cm = 100 * np.asarray(watched.lateral_positions)
        self.s_pans.set_offsets(np.c_[lateral_cm[done], watched.pans[done]])
        self.s_targets.set_offsets(np.c_[lateral_cm[done], watched.targets[done]])
        reading = self._reading(index)
        self.s_title.set_text(reading or f"s ({watched.readout} pan) and α* at l_p")
        self.s_title.set_fontweight("bold" if reading else "normal")
        self.canvas.restore_region(self.background)
        for artist in self.changing:
            self.figure.draw_artist(artist)
        frame = np.array(self.canvas.buffer_rgba())[..., :3]
        self._paste(frame, "side", sample.side)
        self._paste(frame, "eye", self._eye(sample.eye))
        return frame

    def _eye(self, image: np.ndarray) -> np.ndarray:
        """The eye's image at its box's size, the scales' windows drawn on it."""
        left, top, right, bottom = self.boxes["eye"]
        side = right - left
        shown = cv2.resize(image, (side, side), interpolation=cv2.INTER_LINEAR)
        scale, thickness = side / self.image_size, max(1, round(self.font / 4))
        for name, window in self.watched.windows.items():
            corner = (self.image_size - window) / 2 * scale
            first = int(round(corner))
            last = int(round(corner + window * scale)) - 1
            colour = WINDOW_COLOURS.get(name, (255, 255, 0))
            cv2.rectangle(shown, (first, first), (last, last), colour, thickness, cv2.LINE_AA)
        return shown

    def _paste(self, frame: np.ndarray, name: str, picture: np.ndarray) -> None:
        left, top, right, bottom = self.boxes[name]
        size = (right - left, bottom - top)
        if picture.shape[1::-1] != size:
            picture = cv2.resize(picture, size, interpolation=cv2.INTER_AREA)
        frame[top:bottom, left:right] = picture

    def _reading(self, index: int) -> str:
        """The distance read, once the presentation is over."""
        ended = index >= max(i for i, s in enumerate(self.watched.samples) if s.walked_m is None)
        if not ended:
            return ""
        if self.watched.reading is None:
            return "distance: not learnt yet"
        read, truth = self.watched.reading
        off = 100 * abs(read - truth) / truth
        return f"read {read:.2f} m, true {truth:.2f} m ({off:.1f} % off)"

    def regions(self) -> dict[str, tuple[int, int, int, int]]:
        """Each part of the frame, inside its frame line: (left, top, right, bottom) pixels."""
        height = self.size[1]
        boxes = {}
        for name in ("side", "eye", "pan", "s"):
            box = getattr(self, f"{name}_axes").get_window_extent()
            left, right = int(np.ceil(box.x0)) + 1, int(np.floor(box.x1)) - 1
            top, bottom = height - int(np.floor(box.y1)) + 1, height - int(np.ceil(box.y0)) - 1
            boxes[name] = (left, top, right, bottom)
        return boxes

    def close(self) -> None:
        self.figure.clear()


def panel_frames(
    watched: Watched, width: int = 960, picks: Sequence[int] | None = None
) -> Iterator[np.ndarray]:
    """The frames of every pictured sample in order; with ``picks``, only those of them (their
    indices among the pictured samples), so that frames nobody shows are never drawn."""
    pictured = [index for index, sample in enumerate(watched.samples) if sample.pictured]
    chosen = pictured if picks is None else [pictured[k] for k in picks]
    drawer = PanelDrawer(watched, width)
    try:
        for index in chosen:
            yield drawer.draw(index)
    finally:
        drawer.close()


def pictured_count(watched: Watched) -> int:
    return sum(1 for sample in watched.samples if sample.pictured)


def montage_picks(total: int, count: int = 4) -> list[int]:
    """``count`` indices spread evenly over ``total`` frames, the last included."""
    return np.unique(np.linspace(0, total - 1, min(count, total)).round().astype(int)).tolist()


def montage(frames: list[np.ndarray], count: int = 4) -> np.ndarray:
    """``count`` frames spread evenly over ``frames`` (the last included), two to a row."""
    chosen = [frames[i] for i in montage_picks(len(frames), count)]
    if len(chosen) % 2:
        chosen.append(np.full_like(chosen[0], 255))
    rows = [np.concatenate(chosen[i : i + 2], axis=1) for i in range(0, len(chosen), 2)]
    return np.concatenate(rows, axis=0)

"""What a training run shows as it goes: metrics.jsonl, TensorBoard and the progress line.

One :class:`RunLog` per :meth:`parallax.trainer.Trainer.fit`: each presentation's
:class:`parallax.record.PresentationRecord` becomes a line of metrics.jsonl and TensorBoard
scalars (the eye-movement MAE of eq. 16, the distance error of Tables 4–5, the coder's and the
policy's statistics); every train.image_every presentations the dictionaries' atoms, robot 0's
I0 beside I(t) and the video panel of its presentation (parallax.panel); and a progress line: a
tqdm bar on a terminal, else a printed line twenty times a run.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from parallax.coding import MultiScaleCoder
from parallax.panel import montage
from parallax.presentation import Presentation
from parallax.record import PresentationRecord

#: Frames per second of the presentation's video in TensorBoard.
PANEL_FPS = 8


def can_write_video() -> bool:
    """Whether TensorBoard's writer can encode a video here (its add_video needs moviepy)."""
    return importlib.util.find_spec("moviepy") is not None


class RunLog:
    """The run's logs from presentation ``done`` of ``total`` on; a context manager. A resumed
    run (``resumed``) appends, and TensorBoard drops what was written after ``step``, the last
    checkpointed presentation's, which it keeps; a fresh start drops every earlier point."""

    def __init__(self, run_dir: Path, cfg: DictConfig, done: int, step: int, resumed: bool) -> None:
        self.total, self.trials = int(cfg.train.presentations), int(cfg.metrics.summary_trials)
        self.metrics = (run_dir / "metrics.jsonl").open("a")
        # TensorBoard hides every event at or after purge_step: the checkpointed presentation's
        # own point at ``step`` stays, since nothing writes it again
        purge = step + 1 if resumed else 0
        self.writer = SummaryWriter(str(run_dir / "tb"), purge_step=purge)
        if not resumed:
            self.writer.add_text("config", "```yaml\n" + OmegaConf.to_yaml(cfg) + "\n```", 0)
        self.interactive = sys.stderr.isatty()
        self.bar = tqdm(
            total=self.total,
            initial=done,
            desc="presentations",
            unit="pres",
            disable=not self.interactive,
            dynamic_ncols=True,
        )
        self.print_every = max(1, self.total // 20)
        if resumed and done >= self.total:
            print(
                f"[parallax] {run_dir} is finished: it holds {done} presentations "
                f"(train.presentations={self.total}), nothing to train; raise "
                "train.presentations to go on",
                flush=True,
            )

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *error: Any) -> None:
        self.bar.close()
        self.writer.close()
        self.metrics.close()

    def write(self, record: PresentationRecord, steps_per_second: float) -> dict:
        """The presentation's line of metrics.jsonl (returned), its scalars and its progress."""
        line = record.to_json()
        self.metrics.write(json.dumps(line) + "\n")
        self.metrics.flush()
        for tag, value in record.scalars(steps_per_second):
            self.writer.add_scalar(tag, value, record.steps)
        self._progress(record, steps_per_second)
        return line

    def images(self, coder: MultiScaleCoder, pres: Presentation, step: int) -> None:
        """Each scale's atoms, and robot 0's I0 beside its last image if kept."""
        for scale in coder.scales:
            grid = np.asarray(coder.atom_grid(scale))
            fmt = "HW" if grid.ndim == 2 else "HWC"
            self.writer.add_image(f"coder/atoms_{scale}", grid, step, dataformats=fmt)
        if pres.last_view is not None:
            self.writer.add_image("world/I0_beside_It", pres.last_view, step, dataformats="HWC")

    def panel(self, frames: list[np.ndarray], step: int) -> None:
        """Robot 0's presentation, drawn by :mod:`parallax.panel`: a video where TensorBoard can
        write one (it needs the optional moviepy), else a few of its frames as one image."""
        if can_write_video():
            video = np.stack(frames)[None].transpose(0, 1, 4, 2, 3)  # (1, T, C, H, W)
            self.writer.add_video("world/presentation", video, step, fps=PANEL_FPS)
        else:
            self.writer.add_image("world/presentation", montage(frames), step, dataformats="HWC")

    def _progress(self, record: PresentationRecord, steps_per_second: float) -> None:
        distance = record.distance_error.get("total")
        if self.interactive:
            self.bar.set_postfix(
                steps_s=f"{steps_per_second:.0f}",
                mae=f"{record.mae:.3f}",
                recent=f"{record.mae_recent:.3f}",
                dist=f"{distance:.2f}%" if distance is not None else "-",
            )
            self.bar.update(1)
        if record.presentation % self.print_every == 0 or record.presentation == self.total:
            line = (
                f"[parallax] presentation {record.presentation}/{self.total}  "
                f"steps/s {steps_per_second:.0f}  MAE {record.mae:.3f}° "
                f"(last {self.trials} trials {record.mae_recent:.3f}°)  distance error "
                + (f"{distance:.2f}%" if distance is not None else "-")
            )
            # above the bar on a terminal, so that train.log, which keeps no bar, has it too
            if self.interactive:
                self.bar.write(line)
            else:
                print(line, flush=True)

"""Numerical health of a run (beyond the paper): the critic's scale, and whether the policy's
(§3.4) and the distance learner's (§3.5) numbers are still finite, read from each
presentation's record by the trainer.

The critic's bound. The reward of eq. (6), −(eC + eF), lies in [−2, 0] per step (each scale's
reconstruction error is in [0, 1]), so r − J lies in [−2, 2]. A critic that fits its TD targets,
δ = r − J + ξ·v·φ′ − v·φ ≈ 0, has |v·φ| of at most 2/(1 − ξ): about 3 for the recipe's ξ = 0.3,
100 for ξ = 0.98; with ξ = 1 (the TD error as the paper writes it) v·φ is a differential value,
of the order of the reward range times the steps a trial lasts, tens at most. A mean |v·φ|
over a presentation above ``train.critic_scale_warning`` (100) is therefore out of reach of a
critic that converges, and the run says so once: on the terminal and in TensorBoard (text
``health``). It does not stop: a large critic may still come back.

Non-finite numbers. The policy skips an update whose step is not finite, and the
Levenberg–Marquardt fit stops on a non-finite Jacobian; a statistic that overflowed (‖w‖ = inf)
is another sign. A presentation with any of these is unhealthy: the run says so when it starts,
writes no checkpoint while it lasts (the last one written is the last good state) and, after
``train.stop_after_non_finite`` unhealthy presentations in a row, stops with :class:`Diverged`,
leaving :data:`DIVERGED_NAME` in the run directory: the run is over, as one with a summary is,
and the report and compaction tools read it as such. With ``train.stop_after_non_finite=null``
it says so and runs on, checkpoints included, for a study of divergence.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tqdm import tqdm

#: What a run stopped by :class:`Diverged` leaves in its directory (:meth:`Health.stop_record`).
DIVERGED_NAME = "diverged.json"
#: The distance learner's statistics that must be finite once it has fitted (parallax.distance).
_FITTED_STATS = ("lm_loss", "lm_rmse_m", "lm_grad_norm", "lm_mu")


class Diverged(RuntimeError):
    """A run stopped because its numbers stayed non-finite; the message says where and what."""


def _finite(value: Any) -> bool:
    return not isinstance(value, float) or math.isfinite(value)


class Health:
    """The checks of the module docstring, one presentation at a time, with the state a resumed
    run needs to say each thing once, as the uninterrupted run would."""

    def __init__(self, critic_scale_warning: float, stop_after_non_finite: int | None):
        self.critic_scale_warning = float(critic_scale_warning)
        self.stop_after = None if stop_after_non_finite is None else int(stop_after_non_finite)
        self.critic_warned = False
        self.streak = 0  # unhealthy presentations in a row
        self.problems = ""  # what the last unhealthy presentation had
        self.skipped_seen = 0  # the policy's count of skipped updates at the last check

    def problems_in(self, record: Mapping[str, Any], skipped: int, fitted: bool) -> list[str]:
        """What is not finite after the presentation of ``record``: the policy's statistics, its
        ``skipped`` updates, and the distance learner's fit when it ``fitted`` in it."""
        found = [
            f"{k}={v}" for k, v in record.items() if k.startswith("policy_") and not _finite(v)
        ]
        if skipped:
            found.append(f"{skipped} policy update{'s' if skipped > 1 else ''} skipped")
        if fitted:
            found += [f"{k}={record[k]}" for k in _FITTED_STATS if not _finite(record.get(k))]
            if record.get("lm_stopped_non_finite"):
                found.append("the distance fit met a non-finite Jacobian")
        return found

    def check(self, record: Mapping[str, Any], skipped_total: int, fitted: bool) -> list[str]:
        """The lines to show after the presentation of ``record`` ([] most of the time).
        ``skipped_total``: the policy's running count of skipped updates; ``fitted``: whether
        the distance learner fitted in this presentation."""
        lines = []
        presentation = record["presentation"]
        scale = record.get("policy_critic_scale")
        if not self.critic_warned and scale is not None and scale > self.critic_scale_warning:
            self.critic_warned = True
            lines.append(
                f"presentation {presentation}: the critic's scale, mean |v·φ|, reached "
                f"{scale:.4g}, above {self.critic_scale_warning:g} (train.critic_scale_warning), "
                "out of reach of a critic that fits rewards in [−2, 0]: it is diverging; lower "
                "policy.critic_lr"
            )
        problems = self.problems_in(record, skipped_total - self.skipped_seen, fitted)
        self.skipped_seen = skipped_total
        if not problems:
            self.streak, self.problems = 0, ""
            return lines
        self.streak += 1
        self.problems = ", ".join(problems)
        if self.streak == 1:
            then = (
                "running on (train.stop_after_non_finite=null)"
                if self.stop_after is None
                else f"the run stops after {self.stop_after} such presentations in a row "
                "(train.stop_after_non_finite); no checkpoint is written meanwhile"
            )
            lines.append(
                f"presentation {presentation}: numbers stopped being finite ({self.problems}); "
                + then
            )
        return lines

    def report(
        self, record: Mapping[str, Any], skipped_total: int, fitted: bool, writer, step: int
    ) -> None:
        """:meth:`check`, its lines on the terminal (beside a progress bar) and in TensorBoard's
        text ``health`` of ``writer``, with the scalars health/skipped_updates and
        health/non_finite_streak, at ``step``."""
        writer.add_scalar("health/skipped_updates", skipped_total - self.skipped_seen, step)
        for line in self.check(record, skipped_total, fitted):
            tqdm.write(f"[parallax] warning: {line}", file=sys.stderr)
            writer.add_text("health", line, step)
        writer.add_scalar("health/non_finite_streak", self.streak, step)

    @property
    def healthy(self) -> bool:
        return self.streak == 0

    @property
    def must_stop(self) -> bool:
        return self.stop_after is not None and self.streak >= self.stop_after

    def stop_message(self, presentation: int, kept: tuple[Path, int] | None) -> str:
        """Why the run stops after ``presentation``; ``kept``: the last checkpoint written (or
        resumed from) and its presentation, None if there is none."""
        if kept is None:
            kept_line = "no checkpoint was written before it"
        else:
            kept_line = f"its last good checkpoint, {kept[0]} (presentation {kept[1]}), is kept"
        return (
            f"stopped at presentation {presentation}: its numbers have not been finite for "
            f"{self.streak} presentations in a row ({self.problems}); {kept_line}; lower the step "
            "sizes of the learner named (docs/reliability.md), or let a study of divergence run "
            "on with train.stop_after_non_finite=null"
        )

    def stop_record(self, presentation: int, kept: tuple[Path, int] | None) -> dict[str, Any]:
        """What :data:`DIVERGED_NAME` holds when the run stops after ``presentation``: where it
        stopped, the first presentation of the unhealthy streak, what was not finite and the
        last good checkpoint's presentation (None if none); no paths, so that a record moved
        elsewhere stays true."""
        return {
            "stopped_at": presentation,
            "unhealthy_since": presentation - self.streak + 1,
            "problems": self.problems,
            "last_checkpoint": None if kept is None else kept[1],
        }

    def state_dict(self) -> dict[str, Any]:
        return {"critic_warned": self.critic_warned, "streak": self.streak}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.critic_warned = bool(state["critic_warned"])
        self.streak = int(state["streak"])

"""Pan readouts (§3.5): which pan of each trial becomes its component q_p of s.

One class per file (:class:`~parallax.readouts.base.PanReadout`), found by its name: the
values of train.distance_readout are the names in ``READOUTS``. The trainer, parallax-replay
and parallax-eval all read s through :func:`of_run`.
"""

from parallax.readouts.base import PanReadout
from parallax.registry import discover

#: train.distance_readout's value → its readout, one per file of this package.
READOUTS: dict[str, type[PanReadout]] = discover(__name__, __path__, PanReadout)


def of_run(cfg) -> type[PanReadout]:  # type: ignore[no-untyped-def]
    """The readout of a run's ``train.distance_readout`` (a DictConfig or a plain dict)."""
    return READOUTS[str(cfg["train"]["distance_readout"])]


__all__ = ["READOUTS", "PanReadout", "of_run"]

"""The table a run prints at its end (parallax-train): the eye-movement MAE per lateral position
(eq. 16, Tables 2–3), the last trials' mean and variance, the distance error per range (Tables
4–5; a planned route's own, §7) and the wall time, from the trainer's summary."""

from __future__ import annotations


def format_summary(summary: dict, experiment: str | None = None) -> str:
    """The final table printed at the end of a run (``experiment``: the experiment= it ran)."""
    which = f"experiment={experiment}" if experiment else "the schema's defaults (no experiment)"
    lines = [
        f"parallax — {which}, curriculum {summary['curriculum']}, seed {summary['seed']}, "
        f"{summary['presentations']} presentations, {summary['steps']} iterations per robot"
    ]
    last = "last-trials mean, ° (var, °²)"
    lines.append(f"{'position (cm)':>14} {'MAE (°, window)':>16} {last:>30}")
    for label, mae in summary["mae_per_position"].items():
        lt = summary["last_trials"].get(label) or {}
        lines.append(
            f"{label:>14} {_number(mae, '.3f'):>16} {_number(lt.get('mean'), '.3f'):>21} "
            f"({_number(lt.get('var'), '.3f')})"
        )
    lines.append(f"{'all':>14} {_number(summary['mae'], '.3f'):>16}")
    lines.append(_distance_line("distance error (%)", summary["distance_error"]))
    if "route_distance_error" in summary:  # a planned run: its routes' own estimates
        lines.append(
            _distance_line("planned route's distance error (%)", summary["route_distance_error"])
        )
    t = summary["timing"]
    lines.append(f"wall time {t['wall_time_s']:.0f} s, {t['steps_per_second']:.0f} steps/s")
    return "\n".join(lines)


def _number(value: float | None, spec: str) -> str:
    """``value`` formatted, or – where there is none (null, NaN: no trial, no panel there)."""
    if value is None or value != value:
        return "–"
    return format(value, spec)


def _distance_line(title: str, by_range: dict) -> str:
    """``title: 3-4.9 m: 1.23  …  total: 1.00``; a range no panel fell in says so."""
    if not by_range:
        return f"{title}: not yet (the queue of the distance learner is not full)"
    parts = []
    for k, v in by_range.items():
        text = _number(v, ".2f")
        parts.append(
            f"{k if k == 'total' else f'{k} m'}: {'no panel yet' if text == '–' else text}"
        )
    return f"{title}: " + "  ".join(parts)

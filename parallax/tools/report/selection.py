"""Which groups of runs fill the paper's tables: Tables 2–3's columns (a single lateral
position, or the multiple positions 5–10 and 5–20 cm) and Tables 4–5's rows (5–10 cm, 5–20 cm
with and without the weighting of eqs. 10–12), matched by the lateral list L and the weighting.
Where several groups fit a cell, `--prefer KEY=VALUE`, then the number of seeds, decide; the
others are named in the report.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from yaml import YAMLError
from yaml import safe_load as yaml_load

from parallax.config import freeze_value
from parallax.tools.report import paper_results as paper
from parallax.tools.report.groups import Group
from parallax.tools.report.runs import ReportError, total_error


@dataclass
class PaperSelection:
    """Which group fills which column/row of the paper's tables, and the notes about the choice."""

    columns: dict[tuple[str, str], Group]  # (Table 2–3 column, position) -> group
    rows: dict[str, Group]  # Table 4–5 row -> group
    notes: list[str]

    @property
    def empty(self) -> bool:
        return not self.columns and not self.rows


def parse_preferences(items: Iterable[str]) -> dict[str, Any]:
    """``--prefer KEY=VALUE`` options as {dotted key: value}, the value read as YAML (0.1 → 0.1)."""
    preferences: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ReportError(f"--prefer {item!r}: expected KEY=VALUE, e.g. distance.y=0.1")
        try:
            preferences[key.strip()] = freeze_value(yaml_load(value))
        except YAMLError as exc:
            raise ReportError(f"--prefer {item!r}: the value is not YAML ({exc})") from None
    return preferences


def _matches(group: Group, preferences: dict[str, Any]) -> int:
    """How many of the preferred settings the group has."""
    return sum(key in group.flat and group.flat[key] == value for key, value in preferences.items())


def _pick(
    candidates: list[Group],
    what: str,
    notes: list[str],
    prefer_weighting: bool = True,
    preferences: dict[str, Any] | None = None,
) -> Group | None:
    """One group for a table cell: the most preferred settings (``--prefer``), then the most
    seeds, then the preferred weighting; the others noted."""
    if not candidates:
        return None
    preferences = preferences or {}
    ranked = sorted(
        candidates,
        key=lambda g: (
            -_matches(g, preferences),
            -g.n,
            g.weighting_effective != prefer_weighting,
            g.gid,
        ),
    )
    if len(ranked) > 1:
        others = ", ".join(f"{g.gid} ({g.label})" for g in ranked[1:])
        why = (
            "the one with the most of the settings asked for (--prefer)"
            if _matches(ranked[0], preferences) > _matches(ranked[1], preferences)
            else "the one with the most seeds"
        )
        notes.append(
            f"{what}: {len(ranked)} groups fit; shown {ranked[0].gid} ({ranked[0].label}), "
            f"{why}; not shown: {others}."
        )
    return ranked[0]


def select_paper_groups(
    groups: Sequence[Group], preferences: dict[str, Any] | None = None
) -> PaperSelection:
    """Match groups to the paper's columns and rows by their lateral list L and weighting;
    where several fit, ``preferences`` ({setting: value}) decide first."""
    preferences = preferences or {}
    unknown = [
        f"{key}={value!r}"
        for key, value in preferences.items()
        if not any(g.flat.get(key, object()) == value for g in groups)
    ]
    if groups and unknown:
        raise ReportError(f"--prefer {', '.join(unknown)}: no group of runs has that setting")
    notes: list[str] = []
    columns: dict[tuple[str, str], Group] = {}
    for position in paper.TABLE_POSITIONS_CM:
        chosen = _pick(
            [g for g in groups if g.lateral_labels == [position]],
            f"Tables 2–3, {paper.SINGLE} {position} cm",
            notes,
            preferences=preferences,
        )
        if chosen is not None:
            columns[(paper.SINGLE, position)] = chosen
    for column, labels in paper.MULTI_LISTS_CM.items():
        chosen = _pick(
            [g for g in groups if tuple(g.lateral_labels) == labels],
            f"Tables 2–3, {column}",
            notes,
            preferences=preferences,
        )
        if chosen is not None:
            for position in paper.TABLE_POSITIONS_CM:
                if position in labels:
                    columns[(column, position)] = chosen
    rows: dict[str, Group] = {}
    for row, (labels, weighted) in paper.DISTANCE_ROWS.items():
        fits = [
            g
            for g in groups
            if tuple(g.lateral_labels) == labels and g.weighting_effective == weighted
        ]
        # a group whose queue never filled has no distance error: prefer one that has
        measured = [
            g
            for g in fits
            if any(
                total_error(r.online_distance("before")) is not None
                or total_error(r.summary.get("distance_error")) is not None
                for r in g.runs
            )
        ]
        chosen = _pick(
            measured or fits,
            f"Tables 4–5, {row}",
            notes,
            prefer_weighting=weighted,
            preferences=preferences,
        )
        if chosen is not None:
            rows[row] = chosen
    return PaperSelection(columns, rows, notes)

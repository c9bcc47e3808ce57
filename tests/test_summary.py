"""summary.json is strict JSON, and the end summary names what ran and leaves no NaN."""

from __future__ import annotations

import json

import pytest

from parallax.summary import format_summary
from tests.conftest import train_tiny_run


def _strict(text: str) -> dict:
    def refuse(constant: str) -> None:
        raise ValueError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_a_range_without_panels_is_null_in_summary_json_and_said_in_the_summary(tmp_path):
    # panels at 3.0–4.0 m only: no distance of 5–6.9 m or 7–10 m is ever predicted
    train_tiny_run(tmp_path, ["env.distances.stop=4.0"])
    text = (tmp_path / "summary.json").read_text()
    assert "NaN" not in text
    summary = _strict(text)
    assert summary["distance_error"]["7-10"] is None
    assert summary["distance_error"]["total"] > 0
    printed = format_summary(summary, "quickstart")
    first, columns = printed.splitlines()[:2]
    assert first.startswith("parallax — experiment=quickstart, curriculum multi_5_20, seed 0")
    assert "MAE (°, window)" in columns
    assert "7-10 m: no panel yet" in printed and "nan" not in printed.lower()
    assert "no experiment" in format_summary(summary).splitlines()[0]


def test_a_planned_run_prints_its_routes_error(tmp_path):
    summary = {
        "curriculum": "multi_5_20",
        "seed": 1,
        "presentations": 2,
        "steps": 8,
        "mae_per_position": {"5": 0.5},
        "last_trials": {"5": {"mean": None, "var": None}},
        "mae": 0.5,
        "distance_error": {},
        "route_distance_error": {"3-4.9": 2.0, "5-6.9": None, "7-10": 4.0, "total": 3.0},
        "timing": {"wall_time_s": 1.0, "steps_per_second": 8.0},
    }
    printed = format_summary(summary, "planned_multi_5_20_weighted")
    assert (
        "planned route's distance error (%): 3-4.9 m: 2.00  5-6.9 m: no panel yet  "
        "7-10 m: 4.00  total: 3.00"
    ) in printed
    assert "distance error (%): not yet" in printed


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_finite_or_none_leaves_no_constant_json_refuses(value):
    from parallax.metrics import finite_or_none

    cleaned = finite_or_none({"a": [1.0, value], "b": {"c": value}, "d": "x"})
    assert cleaned == {"a": [1.0, None], "b": {"c": None}, "d": "x"}
    json.dumps(cleaned, allow_nan=False)

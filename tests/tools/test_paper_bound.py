"""python -m parallax.tools.analysis.paper_bound: the distance error the paper's published eye
errors allow under stated assumptions (the error model, the estimator)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from parallax.tools.analysis import paper_bound as pb


def test_the_tables_are_the_papers():
    assert pb.EYE_ERROR_DEG["Mult. 5-10 cm", "before"] == {
        5: (0.18, 0.08), 7: (0.16, 0.06), 10: (0.17, 0.06)
    }  # fmt: skip
    assert pb.EYE_ERROR_DEG["Mult. 5-20 cm", "after"][20] == (0.39, 0.13)
    assert pb.LATERAL_LIST_CM["Mult. 5-20 cm"] == list(range(5, 21))
    assert pb.PAPER_DISTANCE_ERROR["after"]["5-20 cm with weighting"]["total"] == 1.30
    mae = pb.per_position({5: 0.18, 7: 0.16, 10: 0.17}, [5, 6, 7, 8, 9, 10])
    assert mae.tolist() == pytest.approx([0.18, 0.17, 0.16, 0.16 + 0.01 / 3, 0.16 + 0.02 / 3, 0.17])


@pytest.mark.parametrize("kind", pb.ERROR_MODELS)
def test_every_error_model_has_the_tables_mean_absolute_error(kind):
    mae, var = np.array([0.18, 0.16, 0.17]), np.array([0.08, 0.06, 0.06])
    model = pb.ErrorModel(kind, mae, var)
    draws = model.draw((200_000, 3), np.random.default_rng(0))
    if kind == "half_bias":  # the drawn part is what is left once the undershoot is removed
        draws = draws - pb.BIAS_SHARE * mae
    np.testing.assert_allclose(np.abs(draws).mean(axis=0), mae, rtol=0.02)


def test_heavy_tails_take_the_degrees_of_freedom_that_give_the_tables_variance():
    assert pb.t_degrees_for(2.0) == pytest.approx(4.0, rel=1e-6)  # Var 2, E|T| 1
    assert pb.t_degrees_for(1.5) == 200.0  # a Gaussian's ratio is π/2 already
    mae, var = np.array([0.18, 0.16, 0.17]), np.array([0.08, 0.06, 0.06])
    model = pb.ErrorModel("heavy_tails", mae, var)
    assert 2.0 < model.nu < 5.0  # 5–10 cm: E e²/MAE² ≈ 3.4, heavier than a Laplace (2)


def test_a_noiseless_eye_leaves_only_the_grid_and_the_small_angle_approximation():
    rows = pb.paper_bounds(samples=2, seed=0, mae_scale=0.0)
    assert len(rows) == 3 * 2 * len(pb.ERROR_MODELS) * len(pb.ESTIMATORS)
    assert all(row["bound"]["total"] < 0.1 for row in rows)


def test_the_posterior_does_at_least_as_well_as_least_squares():
    rows = pb.paper_bounds(samples=15, seed=1)
    by_case = {(r["setup"], r["when"], r["errors"], r["estimator"]): r for r in rows}
    for (setup, when, kind, estimator), row in by_case.items():
        if estimator == "grid_posterior":
            least = by_case[setup, when, kind, "least_squares"]["bound"]["total"]
            assert row["bound"]["total"] < least * 1.02, (setup, when, kind)


def test_the_bound_grows_with_the_eye_error_and_one_seed_gives_one_set_of_numbers():
    once, twice = pb.paper_bounds(samples=10, seed=1), pb.paper_bounds(10, 1, mae_scale=2.0)
    for a, b in zip(once, twice):
        # least squares is linear in small noise; the posterior also gains from the grid's ends
        growth = 1.7 if a["estimator"] == "least_squares" else 1.2
        assert b["bound"]["total"] > growth * a["bound"]["total"], a
    assert pb.paper_bounds(3, seed=3) == pb.paper_bounds(3, seed=3)
    assert pb.paper_bounds(3, seed=3) != pb.paper_bounds(3, seed=4)


def test_cli_prints_the_table_and_writes_the_json(tmp_path, capsys):
    out = tmp_path / "bound.json"
    assert pb.main(["--samples", "2", "--seed", "7", "--json", str(out)]) == 0
    table = capsys.readouterr().out.strip().splitlines()
    assert len(table) == 2 + 6 and table[0].startswith("| set-up |")
    result = json.loads(out.read_text())
    assert result["samples"] == 2 and result["seed"] == 7
    row = result["rows"][0]
    assert row["bound"].keys() == row["paper"].keys() == {"3-4.9", "5-6.9", "7-10", "total"}
    assert row["paper_over_bound"] == pytest.approx(row["paper"]["total"] / row["bound"]["total"])
    assert math.isfinite(row["bound_median"])


def test_cli_refuses_bad_arguments_with_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "bound.json"
    assert pb.main(["--samples", "0", "--json", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert "--samples" in captured.err and not out.exists()
    assert pb.main(["--json", str(tmp_path / "missing" / "bound.json")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "--json" in captured.err
    assert not (tmp_path / "missing").exists()

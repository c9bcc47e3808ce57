"""python -m parallax.tools.analysis.paper_floor: the distance error the paper's published eye
errors allow, if those errors were independent from trial to trial."""

from __future__ import annotations

import json

import pytest

from parallax.tools.analysis import paper_floor as pf


def test_the_tables_are_the_papers():
    assert pf.EYE_MAE_DEG["Mult. 5-10 cm", "before"] == {5: 0.18, 7: 0.16, 10: 0.17}
    assert pf.EYE_MAE_DEG["Mult. 5-20 cm", "after"] == {
        5: 0.16, 7: 0.16, 10: 0.18, 13: 0.21, 15: 0.25, 20: 0.39
    }  # fmt: skip
    assert pf.LATERAL_LIST_CM["Mult. 5-20 cm"] == list(range(5, 21))
    assert pf.PAPER_DISTANCE_ERROR["after"]["5-20 cm with weighting"]["total"] == 1.30
    mae = pf.mae_per_position({5: 0.18, 7: 0.16, 10: 0.17}, [5, 6, 7, 8, 9, 10])
    assert mae.tolist() == pytest.approx([0.18, 0.17, 0.16, 0.16 + 0.01 / 3, 0.16 + 0.02 / 3, 0.17])


def test_a_noiseless_eye_leaves_only_the_small_angle_approximation():
    rows = pf.paper_floors(samples=2, seed=0, mae_scale=0.0)
    assert len(rows) == 12
    assert all(row["floor"]["total"] < 0.1 and row["floor_median"] < 0.1 for row in rows)


def test_the_floor_grows_with_the_eye_error():
    once, twice = pf.paper_floors(samples=50, seed=1), pf.paper_floors(50, 1, mae_scale=2.0)
    for a, b in zip(once, twice):
        assert b["floor"]["total"] > 1.8 * a["floor"]["total"]
        if a["setup"].startswith("5-20"):  # small noise on the nearness: the error is linear
            assert b["floor"]["total"] == pytest.approx(2 * a["floor"]["total"], rel=0.15)


def test_one_seed_gives_one_set_of_numbers():
    assert pf.paper_floors(5, seed=3) == pf.paper_floors(5, seed=3)
    assert pf.paper_floors(5, seed=3) != pf.paper_floors(5, seed=4)


def test_cli_prints_the_table_and_writes_the_json(tmp_path, capsys):
    out = tmp_path / "floor.json"
    assert pf.main(["--samples", "3", "--seed", "7", "--json", str(out)]) == 0
    table = capsys.readouterr().out.strip().splitlines()
    assert len(table) == 2 + 12 and table[0].startswith("| set-up |")
    result = json.loads(out.read_text())
    assert result["samples"] == 3 and result["seed"] == 7 and len(result["rows"]) == 12
    row = result["rows"][0]
    assert row.keys() == {
        "setup", "when", "noise", "floor", "floor_median", "paper", "paper_over_floor"
    }  # fmt: skip
    assert row["floor"].keys() == row["paper"].keys() == {"3-4.9", "5-6.9", "7-10", "total"}
    assert row["paper_over_floor"] == pytest.approx(row["paper"]["total"] / row["floor"]["total"])
    assert result["rows"] == pf.paper_floors(3, seed=7)


def test_cli_refuses_bad_arguments_with_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "floor.json"
    assert pf.main(["--samples", "0", "--json", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert "--samples" in captured.err and not out.exists()
    assert pf.main(["--json", str(tmp_path / "missing" / "floor.json")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert "--json" in captured.err and not (tmp_path / "missing").exists()
    assert pf.main(["--json", str(tmp_path)]) == 2  # a folder
    assert "is a folder" in capsys.readouterr().err

"""python -m parallax.tools.report.ablations: ablations.md from the notes, each ablation's report
and its paired tables, saying which did not run."""

from __future__ import annotations

import pytest

from parallax.tools.report import ablations


def test_ablations_md_gathers_reports_and_paired_tables_and_names_the_missing(tmp_path):
    folder = tmp_path / "ablations"
    folder.mkdir()
    (tmp_path / "ablations_notes.md").write_text("The reading.\n")
    report = "# Ablation: y\n\nintro\n\n## Ablations\n\n| y | error |\n![curve](y.png)\n"
    (folder / "y_paper.md").write_text(report + "\n## Runs\nrest\n")
    (folder / "y_paper_paired.md").write_text("| value | seeds |\n")
    ablations.main([str(tmp_path)])
    text = (tmp_path / "ablations.md").read_text()
    assert text.startswith("# Ablations: what each part buys\n\nThe reading.")
    assert "## Ablation: y" in text and "| y | error |" in text and "## Runs" not in text
    assert "](ablations/y.png)" in text  # figures beside the reports
    assert "Paired (y_paper): | value | seeds |" in text
    assert "## scales: no report (the ablation did not run)" in text
    assert "## queue_recipe: no report" in text


def test_a_root_that_is_not_a_folder_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        ablations.main([str(tmp_path / "missing")])
    assert stop.value.code == 2 and "is not a folder" in capsys.readouterr().err
    assert not (tmp_path / "missing").exists()

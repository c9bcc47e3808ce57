"""`parallax-train --help`: each setting's description and unit from the schema, the experiments
with their length, and what a plain run means."""

from __future__ import annotations

import sys

import pytest
from omegaconf import OmegaConf

from parallax.config import compose
from parallax.config.help import _describe, experiment_length
from parallax.config.plumbing import flatten
from parallax.train import main


def _help(monkeypatch, capsys, *argv: str) -> str:
    monkeypatch.setattr(sys, "argv", ["parallax-train", *argv])
    main()
    return capsys.readouterr().out


def test_help_describes_each_setting_with_this_command_lines_value(monkeypatch, capsys):
    text = _help(monkeypatch, capsys, "env.image_size=64", "--help")
    lines = text.splitlines()
    at = lines.index("  image_size: 64")
    assert lines[at - 1] == (
        "  # Side of the square left-eye image in pixels; the focal length stays 531 px (Table 1)."
    )
    assert (
        "    # Mean lateral speed, metres per iteration (0.002: 5–20 cm in 101 iterations)."
        in lines
    )
    assert "A plain `parallax-train` trains our recipe for 3,000 presentations: hours" in text
    assert "parallax-train experiment=quickstart (250 presentations)" in text
    assert any(line.split() == ["quickstart", "250", "presentations"] for line in lines)
    assert any(line.split() == ["paper_multi_5_20", "800", "presentations"] for line in lines)


def test_every_setting_has_a_description():
    keys = flatten(OmegaConf.to_container(compose([]), resolve=False))
    missing = [k for k in keys if not k.endswith("_target_") and _describe(k) is None]
    assert missing == []


@pytest.mark.parametrize("name", ["quickstart", "continuous_multi_5_20_weighted", "paper_single_5"])
def test_an_experiments_length_is_what_it_composes_to(name):
    assert experiment_length(name) == int(compose([f"experiment={name}"]).train.presentations)


def test_help_with_a_bad_override_is_one_line_and_exit_2(monkeypatch, capsys):
    with pytest.raises(SystemExit) as exit_info:
        _help(monkeypatch, capsys, "env.image_sise=64", "--help")
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "env.image_sise" in line

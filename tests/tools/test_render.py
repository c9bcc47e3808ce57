"""parallax-render: the command the README names draws the README's pictures."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import cv2
import numpy as np

from parallax.tools.render import main

REPO = Path(__file__).resolve().parents[2]


def test_the_readme_command_draws_the_readme_pictures(tmp_path, capsys):
    readme = (REPO / "README.md").read_text()
    (command,) = re.findall(r"`(parallax-render [^`]*)`", readme)
    assert command in (REPO / "docs" / "usage.md").read_text()
    args = shlex.split(command)[1:]
    assert args[args.index("--out") + 1] == "docs"
    args[args.index("--out") + 1] = str(tmp_path)
    assert main(args) == 0
    for name in ("scene_side.png", "scene_left_eye.png"):
        drawn = cv2.imread(str(tmp_path / name)).astype(int)
        shown = cv2.imread(str(REPO / "docs" / name)).astype(int)
        assert drawn.shape == shown.shape
        # the same scene; a renderer of another machine may move an edge pixel or two
        assert np.mean(np.abs(drawn - shown)) < 2.0, name

"""parallax.transcript: the terminal's lines kept in the log, a sweep's lines named."""

from __future__ import annotations

import io
import sys

from parallax import transcript


def test_lines_go_to_the_log_and_a_sweeps_lines_carry_the_run_name(tmp_path, monkeypatch):
    out, err = io.StringIO(), io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setattr(sys, "stderr", err)
    log = tmp_path / "train.log"
    transcript.keep(log, "[seed=1] ")
    try:
        print("[parallax] presentation 1/2")
        sys.stdout.write("two ")
        sys.stdout.write("parts\n")
        sys.stderr.write("\rpresentations:  50%|#####     | 1/2")  # a bar's redraw
        sys.stderr.write("\n")
        print("warning", file=sys.stderr)
        assert not sys.stderr.isatty()  # a sweep's jobs share the terminal: lines, no bars
    finally:
        transcript.release()
    assert sys.stdout is out and sys.stderr is err
    assert out.getvalue() == "[seed=1] [parallax] presentation 1/2\n[seed=1] two parts\n"
    assert err.getvalue().endswith("[seed=1] warning\n")
    assert log.read_text() == "[parallax] presentation 1/2\ntwo parts\nwarning\n"
    transcript.release()  # nothing kept: nothing to do

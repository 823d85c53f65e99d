"""The stderr progress bar: one redrawn line on a terminal, start and end lines otherwise."""

from __future__ import annotations

import io

import pytest

from rig.progress import Progress


def test_not_a_terminal_prints_only_start_and_end() -> None:
    stream = io.StringIO()
    with Progress("process cap", total=3, stream=stream) as progress:
        for note in ("load", "unwrap", "height"):
            progress.step(note)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "process cap: started (3 steps)"
    assert lines[1].startswith("process cap: done in ") and len(lines) == 2


def test_terminal_redraws_one_line_and_clears_it() -> None:
    stream = io.StringIO()
    with Progress("scan", total=4, stream=stream, tty=True) as progress:
        progress.step("frame 1")
        progress.step("frame 2")
    text = stream.getvalue()
    assert "\rscan [############............] 2/4 frame 2" in text and "\n" not in text.split("scan: done")[0]
    assert text.endswith("s\n") and "scan: done in" in text


def test_failure_and_quiet() -> None:
    stream = io.StringIO()
    with pytest.raises(KeyboardInterrupt):
        with Progress("demo", total=1, stream=stream):
            raise KeyboardInterrupt
    assert "demo: interrupted in" in stream.getvalue()
    quiet = io.StringIO()
    with Progress("demo", total=1, stream=quiet, quiet=True) as progress:
        progress.step()
    assert quiet.getvalue() == ""


def test_failure_before_the_first_step_leaves_the_error_line_alone() -> None:
    stream = io.StringIO()
    with pytest.raises(ValueError):
        with Progress("process cap", total=3, stream=stream):
            raise ValueError("bad capture")
    assert stream.getvalue() == ""
    stream = io.StringIO()
    with pytest.raises(ValueError):
        with Progress("process cap", total=3, stream=stream) as progress:
            progress.step("load")
            raise ValueError("corrupt frame")
    assert stream.getvalue().splitlines()[-1].startswith("process cap: failed in ")

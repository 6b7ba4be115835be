"""The one progress UI: plain lines in logs, nothing when off, bars only for real work."""

from __future__ import annotations

import io

from rich.console import Console

from tactbench.ui import Progress


def plain_progress() -> tuple[Progress, io.StringIO]:
    out = io.StringIO()
    bars = Progress(enabled=True)
    bars.__enter__()
    bars._console = Console(file=out, force_terminal=False)  # a log, not a terminal
    return bars, out


def test_disabled_progress_hands_out_no_callbacks():
    with Progress(enabled=False) as bars:
        assert bars.callback("encode") is None
        assert bars.add("encode", total=3) is None


def test_a_callback_shows_nothing_until_it_reports():
    bars, out = plain_progress()
    report = bars.callback("loading dataset")
    assert out.getvalue() == ""  # a cache hit that never reports leaves no trace
    report(0, 2)
    report(2, 2, loss=0.25)
    text = out.getvalue()
    assert "… loading dataset" in text and "✓ loading dataset: 2/2" in text
    assert "loss=0.25" in text


def test_the_total_given_up_front_is_used_when_reports_omit_it():
    bars, out = plain_progress()
    report = bars.callback("encode farneback", total=3)
    for done in (1, 2, 3):
        report(done)
    assert "✓ encode farneback: 3/3" in out.getvalue()

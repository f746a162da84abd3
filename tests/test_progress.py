"""The progress bar draws on a terminal only, never under CI or into a pipe."""

from __future__ import annotations

import io

from planner.app.progress import progress, progress_enabled


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_quiet_when_piped_or_under_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    pipe = io.StringIO()
    assert list(progress(range(5), stream=pipe)) == [0, 1, 2, 3, 4]
    assert pipe.getvalue() == ""
    monkeypatch.setenv("CI", "true")
    assert not progress_enabled(FakeTerminal())


def test_draws_on_a_terminal(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    term = FakeTerminal()
    assert list(progress(range(3), label="bench", stream=term)) == [0, 1, 2]
    assert "bench [" in term.getvalue() and "3/3" in term.getvalue()

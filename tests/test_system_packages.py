"""A missing system package fails the test that needs it; it skips only on explicit opt-out,
and never in CI."""

import pytest
from system_packages import OPT_OUT, require


def test_missing_package_fails_unless_opted_out_outside_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv(OPT_OUT, raising=False)
    with pytest.raises(pytest.fail.Exception, match=r"libfoo missing — run scripts/setup\.sh"):
        require(False, "libfoo missing")
    monkeypatch.setenv(OPT_OUT, "1")
    with pytest.raises(pytest.skip.Exception, match="libfoo"):
        require(False, "libfoo missing")
    monkeypatch.setenv("CI", "true")  # CI ignores the opt-out
    with pytest.raises(pytest.fail.Exception, match=r"setup\.sh"):
        require(False, "libfoo missing")
    require(True, "never raised")

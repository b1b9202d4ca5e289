"""Missing system packages skip on a developer machine and fail in CI."""

import pytest
from system_packages import require


def test_missing_package_fails_in_ci_and_skips_elsewhere(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match=r"setup\.sh"):
        require(False, "libfoo missing")
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception, match="libfoo"):
        require(False, "libfoo missing")
    require(True, "never raised")

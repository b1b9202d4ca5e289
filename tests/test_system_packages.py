"""A missing system package fails the test that needs it, in CI and outside it, whatever the
environment says (the old skip opt-out is gone)."""

import pytest
from system_packages import require


@pytest.mark.parametrize(
    "env", [{}, {"CI": "true"}, {"DEXCANVAS_ALLOW_MISSING_SYSTEM_PACKAGES": "1"}]
)
def test_missing_package_fails(monkeypatch, env):
    for k in ("CI", "DEXCANVAS_ALLOW_MISSING_SYSTEM_PACKAGES"):
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    with pytest.raises(pytest.fail.Exception, match=r"libfoo missing — run scripts/setup\.sh"):
        require(False, "libfoo missing")
    require(True, "never raised")

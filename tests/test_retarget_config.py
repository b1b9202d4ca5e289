"""``RetargetConfig``: term configs composed, dotted and flat names, validation at construction."""

from __future__ import annotations

import dataclasses

import pytest

from retarget.config import (
    FLAT_NAMES,
    ContactsConfig,
    GripConfig,
    RetargetConfig,
    SolverConfig,
    resolve_name,
)
from retarget.errors import RetargetError
from retarget.overrides import build_config

RUN_OPTIONS = {"backend": "--backend", "force_matching": "--forces", "force_scale": "--force-scale"}


def test_every_setting_has_one_flat_name_and_flat_lists_them_in_order():
    cfg = RetargetConfig()
    assert sorted(FLAT_NAMES.values()) == sorted(RetargetConfig.setting_names())
    assert len(set(FLAT_NAMES.values())) == len(FLAT_NAMES)
    flat = cfg.flat()
    assert list(flat) == list(FLAT_NAMES)
    # a few of the defaults, under the names metrics.json records them by
    assert flat["w_contacts"] == 200.0 and flat["contact_tangent_weight"] == 0.01
    assert flat["backend"] == "pinocchio" and flat["solver"] == "daqp"
    assert flat["joint_limit_margin"] is None and flat["grip"] == "wrench"
    assert RetargetConfig.from_overrides(flat) == cfg


def test_flat_and_dotted_names_build_the_same_config():
    a = RetargetConfig.from_overrides({"w_contacts": 100.0, "grip": "depth"})
    b = RetargetConfig.from_overrides({"contacts.weight": 100.0, "grip.mode": "depth"})
    c = RetargetConfig(contacts=ContactsConfig(weight=100.0), grip=GripConfig(mode="depth"))
    assert a == b == c
    assert a.get("w_contacts") == a.get("contacts.weight") == a.contacts.weight == 100.0
    # applied in order: a later name for the same setting wins
    d = RetargetConfig.from_overrides({"contacts.enabled": True, "use_contacts": False})
    assert d.contacts.enabled is False
    # the other settings keep their defaults
    assert dataclasses.replace(a, contacts=ContactsConfig(), grip=GripConfig()) == RetargetConfig()


def test_unknown_names_list_the_settings_and_close_matches():
    with pytest.raises(RetargetError, match=r"'w_contact' \(did you mean .*w_contacts") as e:
        resolve_name("w_contact")
    assert "contacts.weight" in str(e.value)
    with pytest.raises(RetargetError, match=r"contacts\.wieght \(did you mean contacts\.weight"):
        build_config(RetargetConfig, {"contacts.wieght": 1.0})


def test_choices_and_ranges_are_checked_at_construction():
    with pytest.raises(RetargetError, match=r"SolverConfig\.backend: unknown value 'pin'"):
        SolverConfig(backend="pin")
    with pytest.raises(RetargetError, match=r"ContactsConfig\.weight must be finite and >= 0"):
        RetargetConfig.from_overrides({"w_contacts": -1.0})
    with pytest.raises(RetargetError, match=r"RetargetConfig\.contacts must be a ContactsConfig"):
        RetargetConfig(contacts=GripConfig())


def test_build_config_reserves_the_runs_own_options_under_either_name():
    cfg = build_config(
        RetargetConfig, {"contacts.weight": 50.0}, "--set", RUN_OPTIONS,
        backend="mink", force_matching=True, force_scale=1.5,
    )  # fmt: skip
    assert cfg.contacts.weight == 50.0 and cfg.solver.backend == "mink"
    assert cfg.force_matching.enabled and cfg.force_matching.scale == 1.5
    for name in ("backend", "solver.backend"):
        with pytest.raises(RetargetError, match=f"{name} is the run's own option, use --backend"):
            build_config(RetargetConfig, {name: "mink"}, "--set", RUN_OPTIONS)
    with pytest.raises(RetargetError, match=r"--set: RetargetConfig refuses .*w_smooth"):
        build_config(RetargetConfig, {"w_smooth": -1.0}, "--set", RUN_OPTIONS)

"""``--help`` of both command lines teaches (description, examples, defaults, exit codes); one
``--dataset PATH|builtin`` option; ``dexcanvas cache path|clear|rebuild``."""

import argparse
import io
import json

import pytest

from dexcanvas_core import cli as dcli
from dexcanvas_core import cli_parser as dparser
from dexcanvas_core import open_dataset
from dexcanvas_core.builtin import builtin_pair_path
from dexcanvas_core.cli_help import HelpFormatter
from dexcanvas_core.errors import DatasetError
from retarget import cli as rcli
from retarget import cli_args as rargs


def _subparsers(parser: argparse.ArgumentParser, prefix: str):
    """``(command line, parser)`` of every command and sub-command under ``parser``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield f"{prefix} {name}", sub
                yield from _subparsers(sub, f"{prefix} {name}")


COMMANDS = [
    *_subparsers(dparser.build_parser(), "dexcanvas"),
    *_subparsers(rcli.build_parser(), "retarget"),
]


def _needs_default(action: argparse.Action) -> bool:
    d = action.default
    return bool(action.option_strings) and not (
        d is None or d is argparse.SUPPRESS or isinstance(d, bool) or d in ([], ())
    )


@pytest.mark.parametrize("command, parser", COMMANDS, ids=[c for c, _ in COMMANDS])
def test_every_command_has_description_examples_and_defaults(command, parser):
    assert parser.description and len(parser.description) > 20, command
    assert parser.formatter_class is HelpFormatter, command
    text = parser.format_help()
    assert "examples:" in text, command
    examples = parser.epilog.split("examples:\n", 1)[1].splitlines()
    assert 1 <= len(examples) <= 3, command
    assert any(line.strip().startswith(command.split()[0]) for line in examples), command
    fmt = parser._get_formatter()
    for action in parser._actions:
        if _needs_default(action):
            help_text = fmt._get_help_string(action)
            assert "default" in help_text, f"{command} {action.option_strings}"
            assert "default: None" not in text, command


def test_top_level_help_lists_the_exit_codes():
    for parser in (dparser.build_parser(), rcli.build_parser()):
        text = parser.format_help()
        for code in ("0 ", "1 ", "2 ", "3 ", "130"):
            assert f"  {code}" in text
        assert "exit codes:" in text and "examples:" in text


def test_defaults_are_shown_and_floats_read_well():
    text = _parser_of("dexcanvas synthesize").format_help()
    assert "(default: 10)" in text and "(default: 30)" in text  # --expand, --yaw-deg
    text = _parser_of("retarget run").format_help()
    assert "(default: pinocchio)" in text and "(default: 0)" in text


def _parser_of(command: str) -> argparse.ArgumentParser:
    return dict(COMMANDS)[command]


# ---------------------------------------------------------------------------- --dataset


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    out = tmp_path_factory.mktemp("help") / "ex.lance"
    assert dcli.main(["example", "--out", str(out)]) == 0
    return out


@pytest.fixture
def builtin_is_example(example, monkeypatch):
    """``--dataset builtin`` resolves to the example (building the whole set is slow)."""
    asked = []

    def fake(progress=None):
        asked.append(progress)
        return example

    monkeypatch.setattr(dcli, "default_dataset_path", fake)
    return asked


def test_dataset_builtin_for_info_validate_export(builtin_is_example, tmp_path, capsys):
    assert dcli.main(["info", "--dataset", "builtin", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == 18
    assert dcli.main(["validate", "--dataset", "builtin"]) == 0
    assert "18 of 18 rows valid" in capsys.readouterr().out
    out = tmp_path / "b.parquet"
    argv = ["export", "--dataset", "builtin", "--parquet", str(out), "--objects", "cube2"]
    assert dcli.main(argv) == 0 and out.exists()
    assert builtin_is_example == [True, True, True]  # built with progress


def test_positional_dataset_is_a_deprecated_alias(example, capsys):
    assert dcli.main(["info", str(example), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == 18
    assert "deprecated" in _parser_of("dexcanvas info").format_help()
    assert dcli.main(["info", str(example), "--dataset", str(example)]) == 2
    assert "given twice" in capsys.readouterr().err
    assert dcli.main(["validate"]) == 2
    assert "--dataset PATH" in capsys.readouterr().err


def test_dataset_builtin_in_the_retarget_and_simulate_configs(tmp_path):
    args = rcli.build_parser().parse_args(
        ["run", "--hand", "shadow", "--pair", "cube2/tripod", "--dataset", "builtin"]
    )
    assert rargs._plain_run_config(args).dataset is None
    args = rcli.build_parser().parse_args(["run", "--hand", "shadow", "--dataset", "./builtin"])
    assert str(rargs._plain_run_config(args).dataset) == "builtin"  # a directory of that name
    args = dparser.build_parser().parse_args(
        ["simulate", "--dataset", "builtin", "--out", str(tmp_path / "s.lance")]
    )
    assert args.dataset == "builtin"


# ---------------------------------------------------------------------------- dexcanvas cache


@pytest.fixture
def cache(tmp_path, monkeypatch):
    root = tmp_path / "cache"
    monkeypatch.setenv("DEXCANVAS_CACHE_DIR", str(root))
    return root


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_cache_path_rebuild_clear(cache, capsys, monkeypatch):
    assert dcli.main(["cache", "path"]) == 0
    assert str(cache) in capsys.readouterr().out
    assert dcli.main(["cache", "rebuild", "--pairs", "cube2/tripod"]) == 0
    built = builtin_pair_path("cube2/tripod")
    assert f"built {built}" in capsys.readouterr().out
    assert len(open_dataset(built)) == 1
    assert dcli.main(["cache", "path"]) == 0
    out = capsys.readouterr().out
    assert "builtin-demos-" in out and "built-in demonstrations" in out
    assert dcli.main(["cache", "rebuild", "--pairs", "cube2/nonsense"]) == 2
    capsys.readouterr()
    # clear: no terminal and no --yes → refused; a terminal answering no → kept
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    assert dcli.main(["cache", "clear"]) == 2
    assert "--yes" in capsys.readouterr().err and built.exists()
    monkeypatch.setattr("sys.stdin", _Terminal("n\n"))
    assert dcli.main(["cache", "clear"]) == 0
    assert "nothing removed" in capsys.readouterr().out and built.exists()
    (cache / "logs").mkdir()
    assert dcli.main(["cache", "clear", "--yes"]) == 0
    assert "removed 1 entries" in capsys.readouterr().out
    assert not built.exists() and (cache / "logs").is_dir()  # tracebacks stay


def test_corrupt_builtin_cache_says_cache_rebuild(cache, capsys):
    assert dcli.main(["cache", "rebuild", "--pairs", "cube2/tripod"]) == 0
    path = builtin_pair_path("cube2/tripod")
    for f in (path / "_versions").iterdir():
        f.write_bytes(b"garbage")
    with pytest.raises(DatasetError, match="dexcanvas cache rebuild"):
        open_dataset(path).info()
    assert dcli.main(["info", "--dataset", str(path)]) == 2
    assert "dexcanvas cache rebuild" in capsys.readouterr().err
    assert dcli.main(["cache", "rebuild", "--pairs", "cube2/tripod"]) == 0
    assert len(open_dataset(path)) == 1

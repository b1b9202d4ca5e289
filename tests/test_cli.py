import json
import subprocess
import sys

import pytest

from dexcanvas_core.cli import main


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "ex.lance"
    assert main(["example", "--out", str(out)]) == 0
    return out


def test_info_json(example, capsys):
    assert main(["info", "--dataset", str(example), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["rows"] == 18 and d["fps"] == {"120": 18}
    assert d["operators"] == {"operator1": 6, "operator2": 6, "operator3": 6}
    assert d["pairs"]["cube2/tripod"] == 3 and d["size_bytes"] > 0


def test_info_table_and_validate(example, capsys):
    assert main(["info", "--dataset", str(example)]) == 0
    out = capsys.readouterr().out
    assert "cube2/tripod" in out and "operator3" in out
    assert main(["validate", "--dataset", str(example)]) == 0
    assert "18 of 18 rows valid" in capsys.readouterr().out


def test_export_filtered(example, tmp_path, capsys):
    import pyarrow.parquet as pq

    out = tmp_path / "x.parquet"
    argv = ["export", "--dataset", str(example), "--parquet", str(out), "--objects", "cube2"]
    assert main(argv) == 0
    assert pq.read_table(out).num_rows == 3


def test_errors_are_one_line_with_exit_2(example, tmp_path, capsys):
    assert main(["info", "--dataset", str(tmp_path / "missing.lance")]) == 2
    err = capsys.readouterr().err
    assert "dexcanvas info: error:" in err and "no such dataset" in err
    assert main(["example", "--out", str(tmp_path)]) == 2  # exists, no --overwrite
    assert "already exists" in capsys.readouterr().err
    assert main(["export", "--dataset", str(example), "--parquet", str(tmp_path / "o.parquet"),
                 "--objects", "cub2"]) == 2  # fmt: skip
    assert "did you mean 'cube2'" in capsys.readouterr().err


def test_entry_points_answer_help():
    for mod in ("dexcanvas_core.cli", "retarget.cli"):
        r = subprocess.run([sys.executable, "-m", mod, "--help"], capture_output=True, text=True)
        assert r.returncode == 0 and "usage:" in r.stdout

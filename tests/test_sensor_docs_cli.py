"""docs/sensors.md holds the tables the code renders; the `biso-cosim sensor` command."""

import argparse
import json
from pathlib import Path

import pytest

from biso_cosim.cli import sensor as sensor_cli
from biso_cosim.sensors import parameter_schema
from biso_cosim.sensors.table import chip_table, fill_docs, parameter_table

DOCS = Path(__file__).resolve().parents[1] / "docs" / "sensors.md"


def run(*argv):
    parser = argparse.ArgumentParser()
    sensor_cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["sensor", *argv])
    return args.func(args)


def test_docs_tables_are_in_sync_with_the_data():
    text = DOCS.read_text(encoding="utf-8")
    assert fill_docs(text) == text, "run: biso-cosim sensor table --docs docs/sensors.md"
    table = parameter_table()
    for key in parameter_schema():
        assert f"`{key}`" in table


def test_tables_show_values_sources_and_peers():
    table = parameter_table()
    assert "| `gyro.noise_density` | N_g | 0.01 | °/s/√Hz | value | [PS] §3.1" in table
    assert "| `accel.bias_initial` | b_a0 | [60, 60, 80] | mg | ± tol." in table
    chip = chip_table()
    assert "±250 °/s: 131 LSB/(°/s)" in chip and "3: 41 Hz / 5.9 ms / 1 kHz" in chip


def test_cli_table_info_and_allan(tmp_path, capsys):
    assert run("table") == 0
    assert "## Error parameters" in capsys.readouterr().out
    assert run("info", "--set", "smplrt_div=9", "--set", "mag_bit16=false") == 0
    out = capsys.readouterr().out
    assert "ODR   100 Hz" in out and "14-bit" in out
    code = run("allan", "--hours", "0.01", "--out", str(tmp_path))
    results = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))
    # 36 s is too short for the 10 % check to be reliable; the exit code reports it
    assert results["hours"] == 0.01 and code == (0 if results["pass"] else 1)
    assert "Allan deviation at 1 s / noise density" in capsys.readouterr().out
    copy = tmp_path / "sensors.md"
    copy.write_text(DOCS.read_text(encoding="utf-8").replace("| `gyro.noise_density` |", "| stale |", 1), encoding="utf-8")
    assert run("table", "--docs", str(copy)) == 0
    assert copy.read_text(encoding="utf-8") == DOCS.read_text(encoding="utf-8")


def test_cli_bad_arguments_are_named():
    with pytest.raises(ValueError, match="--set expects FIELD=VALUE"):
        run("info", "--set", "smplrt_div")
    with pytest.raises(ValueError, match="registers.smplrt_div"):
        run("info", "--set", "smplrt_div=999")
    with pytest.raises(ValueError, match="--hours"):
        run("allan", "--hours", "-1", "--out", "x")

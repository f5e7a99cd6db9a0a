"""Every bad input of the command line is one line on stderr, exit code 2, naming the file or
argument and what was expected (no traceback, no numpy repr). The list of bad inputs tried
is this file's BAD_INPUTS; the files they use are made by ``_files``."""

from __future__ import annotations

import subprocess
import sys

import pytest

from biso_cosim.cli import main as cli_main

LOG_HEADER = ("t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2,"
              "mag_x_ut,mag_y_ut,mag_z_ut")


def _files(tmp_path):
    rows = [f"{t!r},0,0,0,0,0,9.81,20,0,-40" for t in (0.0, 0.005, 0.010, 0.0075, 0.020)]
    (tmp_path / "backwards.csv").write_text(LOG_HEADER + "\n" + "\n".join(rows) + "\n")
    good = [f"{0.005 * i:.3f},0,0,0,0,0,9.81,20,0,-40" for i in range(20)]
    (tmp_path / "good.csv").write_text(LOG_HEADER + "\n" + "\n".join(good) + "\n")
    (tmp_path / "binary.csv").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "nul.csv").write_bytes(b"t_s\x00,gyro\x00\n")
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "a_file").write_text("not a directory\n")
    (tmp_path / "track.gpx").write_text('<?xml version="1.0"?><gpx version="1.1"><trk><trkseg>'
                                        '<trkpt lat="51.5" lon="46.0"/><trkpt lat="51.501" lon="46.0"/>'
                                        "</trkseg></trk></gpx>\n")
    (tmp_path / "bad.toml").write_bytes(b"\xff\xfe\x00garbage")


# (argv with {d} for the directory of the files, the words the one-line message must hold)
BAD_INPUTS = [
    (["estimate", "{d}/good.csv", "--out", "{d}/o.csv", "--fs", "0.001"], ["--fs", "0.001", "Hz"]),
    (["estimate", "{d}/good.csv", "--out", "{d}/o.csv", "--fs", "1e300"], ["--fs", "Hz"]),
    (["estimate", "{d}/good.csv", "--out", "{d}/o.csv", "--fs", "nan"], ["--fs"]),
    (["estimate", "{d}/backwards.csv", "--out", "{d}/o.csv"],
     ["backwards.csv", "line 5 (data row 4)", "t_s must increase", "t = 0.0075 s follows t = 0.01 s"]),
    (["estimate", "{d}/binary.csv", "--out", "{d}/o.csv"], ["binary.csv", "binary file"]),
    (["estimate", "{d}/nul.csv", "--out", "{d}/o.csv"], ["nul.csv", "binary file"]),
    (["estimate", "{d}/a_dir", "--out", "{d}/o.csv"], ["a_dir", "is a directory", "CSV"]),
    (["estimate", "{d}/missing.csv", "--out", "{d}/o.csv"], ["missing.csv", "does not exist"]),
    (["estimate", "{d}/good.csv", "--out", "{d}/good.csv"], ["--out", "good.csv", "is the input"]),
    (["estimate", "{d}/good.csv", "--out", "{d}/a_dir"], ["--out", "a_dir", "is a directory"]),
    (["estimate", "{d}/good.csv", "--out", "/proc/o.csv"], ["--out", "/proc", "cannot write"]),
    (["estimate", "{d}/good.csv", "--out", "{d}/o.csv", "--method", "nope"], ["--method", "nope", "known"]),
    (["estimate", "{d}/good.csv", "--out", "{d}/o.csv", "--summary", "{d}/a_file"],
     ["--summary", "a_file", "summary.json"]),
    (["run", "--route", "{d}/a_dir", "--out", "{d}/o"], ["a_dir", "is a directory", ".toml"]),
    (["run", "--route", "{d}/bad.toml", "--out", "{d}/o"], ["bad.toml", "UTF-8"]),
    (["run", "--route", "{d}/nothere.toml", "--out", "{d}/o"], ["nothere.toml", "does not exist"]),
    (["run", "--route", "figure8", "--out", "{d}/a_file"], ["--out", "a_file", "existing file", "directory"]),
    (["run", "--route", "figure8", "--out", "{d}/a_file/sub"], ["--out", "a_file", "is a file"]),
    (["run", "--route", "figure8", "--out", "/proc/biso_run"], ["--out", "/proc", "cannot write"]),
    (["run", "--route", "figure8", "--duration", "-5", "--out", "{d}/o"], ["--duration", "-5"]),
    (["run", "--route", "figure8", "--duration", "inf", "--out", "{d}/o"], ["--duration"]),
    (["run", "--route", "figure8", "--seed", "-1", "--out", "{d}/o"], ["--seed", "-1"]),
    (["run", "--route", "nowhere", "--out", "{d}/o"], ["nowhere", "known routes"]),
    (["run", "--route", "figure8", "--sensor-profile", "{d}/a_dir", "--out", "{d}/o"], ["a_dir"]),
    (["compare", "--out", "{d}/a_file", "--routes", "", "--motions", "tumble"], ["--out", "a_file", "directory"]),
    (["routes", "import", "{d}/track.gpx", "--out", "{d}/track.gpx"], ["--out", "track.gpx"]),
    (["score", "{d}/a_dir", "--out", "{d}/o"], ["DIR", "a_dir", "no recordings"]),
    (["score", "{d}/nowhere", "--out", "{d}/o"], ["DIR", "nowhere", "does not exist"]),
    (["routes", "import", "{d}/a_dir", "--out", "{d}/r.toml"], ["a_dir"]),
    (["routes", "import", "{d}/binary.csv", "--out", "{d}/r.toml"], ["binary.csv"]),
]


@pytest.mark.parametrize("argv, words", BAD_INPUTS, ids=[" ".join(a[:2]) + f" #{i}" for i, (a, _) in
                                                        enumerate(BAD_INPUTS)])
def test_bad_input_is_one_line_naming_it(tmp_path, capsys, argv, words):
    _files(tmp_path)
    args = [a.format(d=tmp_path) for a in argv]
    assert cli_main(args) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert line.startswith(f"biso-cosim {args[0]}") and "error" in line, line
    for word in words:
        assert word in line, (word, line)
    assert "np.float64" not in line and "Traceback" not in captured.err
    assert not (tmp_path / "o").exists()  # refused before any work


def test_no_traceback_from_the_installed_command(tmp_path):
    """The same through a real process (what a user sees): one line, exit 2."""
    _files(tmp_path)
    proc = subprocess.run([sys.executable, "-c", "import sys; from biso_cosim.cli import main; sys.exit(main())",
                           "estimate", str(tmp_path / "backwards.csv"), "--out", str(tmp_path / "o.csv")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr

"""``biso-cosim routes import/show/check``: every bad input is one line naming the file or the
option and what was expected (exit code 2, no traceback), checked before any work; outputs
never overwrite an input and are written whole."""

import re
from pathlib import Path

import numpy as np
import pytest

from biso_cosim.cli import main
from biso_cosim.routes.synthetic import synthetic_track, write_gpx

GOOD_ROUTE = 'name = "r"\ndescription = "d"\nclosed = false\n[[waypoint]]\nx_m = 0.0\ny_m = 0.0\n' \
             '[[waypoint]]\nx_m = 50.0\ny_m = 0.0\n'


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    write_gpx(synthetic_track("urban", length_m=400.0, rate_hz=1.0, seed=31, stop_at=[(200.0, 8.0)]).track,
              d / "drive.gpx")
    lines = (d / "drive.gpx").read_text().splitlines()
    bad = list(lines)
    bad[10] = re.sub(r'lat="[0-9.]+"', 'lat="149.4"', bad[10])
    (d / "lat.gpx").write_text("\n".join(bad) + "\n")
    back = list(lines)
    back[12] = re.sub(r"<time>[^<]+</time>", "<time>2024-05-01T08:00:00.000Z</time>", back[12])
    (d / "back.gpx").write_text("\n".join(back) + "\n")
    (d / "binary.gpx").write_bytes(bytes(range(256)) * 4)
    (d / "empty.gpx").write_text("")
    (d / "folder.gpx").mkdir()
    (d / "notes.txt").write_text("not a directory\n")
    (d / "route.toml").write_text(GOOD_ROUTE)
    (d / "broken.toml").write_text("name = 'x'\nclosed = \n")
    (d / "binary.toml").write_bytes(b"\x00\x01\x02\xff" * 64)
    (d / "folder.toml").mkdir()
    import pymap3d

    a = np.arange(0.0, 100.0, 5.0)  # a square corner every 5 m: smoothed further with a warning
    e, n = np.concatenate([a, np.full(a.size, 100.0)]), np.concatenate([np.zeros(a.size), a])
    lat, lon, _ = pymap3d.enu2geodetic(e, n, np.zeros(e.size), 51.5, 46.0, 0.0)
    body = "\n".join(f'<trkpt lat="{la:.8f}" lon="{lo:.8f}"/>' for la, lo in zip(lat, lon))
    (d / "corner.gpx").write_text(f'<gpx version="1.1"><trk><trkseg>\n{body}\n</trkseg></trk></gpx>\n')
    return d


def run(capsys, *argv):
    rc = main(["routes", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


# (arguments with {d} for the files' directory, what the one-line message must say)
BAD = [
    (["import", "{d}/missing.gpx", "--out", "{d}/x.toml"], r"track file '.*missing.gpx' does not exist"),
    (["import", "{d}/folder.gpx", "--out", "{d}/x.toml"], r"folder.gpx is a directory; expected a .gpx or .csv"),
    (["import", "{d}/binary.gpx", "--out", "{d}/x.toml"], r"binary.gpx is a binary file; expected a GPX text file"),
    (["import", "{d}/empty.gpx", "--out", "{d}/x.toml"], r"empty.gpx is empty; expected a GPX track"),
    (["import", "{d}/lat.gpx", "--out", "{d}/x.toml"], r"lat.gpx, line 11: track point 8 has lat=149.4; expected a "
                                                        r"latitude in \[-90, 90\] degrees"),
    (["import", "{d}/back.gpx", "--out", "{d}/x.toml"], r"back.gpx, line 13: track point 10's time is \d+ s earlier"),
    (["import", "{d}/notes.txt", "--out", "{d}/x.toml"], r"notes.txt: expected a .gpx or .csv track, got '.txt'"),
    (["import", "{d}/drive.gpx", "--out", "{d}/drive.gpx"], r"--out '.*drive.gpx' is the input '.*drive.gpx'"),
    (["import", "{d}/drive.gpx", "--out", "{d}"], r"--out '.*' is a directory; expected a file name"),
    (["import", "{d}/drive.gpx", "--out", "{d}/x.json"], r"--out '.*x.json': expected a .toml file"),
    (["import", "{d}/drive.gpx", "--out", "{d}/notes.txt/x.toml"], r"--out .*notes.txt' is a file, not a directory"),
    (["import", "{d}/drive.gpx", "--out", "/proc/x.toml"], r"--out '/proc/x.toml': cannot write in '/proc'"),
    (["import", "{d}/drive.gpx", "--out", "{d}/x.toml", "--speed", "-1"], r"speed_mps must be a positive number"),
    (["import", "{d}/drive.gpx", "--out", "{d}/x.toml", "--smoothing", "0"], r"smoothing_m must be a positive number"),
    (["import", "{d}/drive.gpx", "--out", "{d}/x.toml", "--max-length-km", "0.1"],
     r"drive.gpx: the track is 4\d\d.\d m long, more than the 0.1 km a route may be"),
    (["import", "{d}/drive.gpx", "--out", "{d}/x.toml", "--max-file-mb", "0.0001"],
     r"drive.gpx is 0 MB, more than the 0.0001 MB a track may have"),
    (["show", "nowhere", "--out", "{d}/m.png"], r"unknown route 'nowhere'; known routes: .*loop600"),
    (["show", "{d}/missing.toml", "--out", "{d}/m.png"], r"route file '.*missing.toml' does not exist"),
    (["show", "{d}/folder.toml", "--out", "{d}/m.png"], r"route file '.*folder.toml' is a directory"),
    (["show", "{d}/broken.toml", "--out", "{d}/m.png"], r"broken.toml: not valid TOML"),
    (["show", "{d}/binary.toml", "--out", "{d}/m.png"], r"binary.toml: not UTF-8 text \(byte 3\); expected a TOML route file"),
    (["show", "{d}/route.toml", "--out", "{d}/route.toml"], r"--out '.*route.toml' is the input"),
    (["show", "figure8", "--out", "{d}"], r"--out '.*' is a directory"),
    (["show", "figure8", "--out", "{d}/m.txt"], r"--out '.*m.txt': expected a .png or .pdf or .svg file"),
    (["check", "nowhere"], r"unknown route 'nowhere'"),
    (["check", "figure8", "--out", "{d}"], r"--out '.*' is a directory"),
    (["check", "figure8", "--out", "{d}/c.csv"], r"--out '.*c.csv': expected a .json file"),
]


@pytest.mark.parametrize(("argv", "message"), BAD, ids=[" ".join(a[:2]) + f" #{i}" for i, (a, _) in enumerate(BAD)])
def test_bad_inputs_are_one_line(files, capsys, argv, message):
    rc, out, err = run(capsys, *[a.format(d=files) for a in argv])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("biso-cosim routes: error: ")
    assert "Traceback" not in err and "np.float64" not in err and "array(" not in err
    assert re.search(message, lines[0]), lines[0]
    assert not (files / "x.toml").exists()


def test_import_writes_the_route_and_leaves_the_input(files, capsys, tmp_path):
    before = (files / "drive.gpx").read_bytes()
    rc, out, err = run(capsys, "import", files / "drive.gpx", "--out", tmp_path / "new" / "drive.toml")
    assert rc == 0, err
    assert (files / "drive.gpx").read_bytes() == before
    assert re.search(r"drive: 0.\d\d km, open, 1 stop\(s\), about \d+ s; \d+ of \d+ points used", out)
    from biso_cosim.routes import load_route

    route = load_route(str(tmp_path / "new" / "drive.toml"))
    assert f"{route.path.length_m / 1000:.2f} km" in out and f"{route.path.length_m / 1000:.2f} km" in route.description
    assert list((tmp_path / "new").iterdir()) == [tmp_path / "new" / "drive.toml"]


def test_import_warnings_are_one_line_each(files, capsys, tmp_path):
    rc, out, err = run(capsys, "import", files / "corner.gpx", "--out", tmp_path / "c.toml", "--no-progress")
    assert rc == 0
    warning = [line for line in err.splitlines() if "warning" in line]
    # the smoothing of the corner, and the recorded speed its curve caps (naming the waypoint)
    assert len(warning) == 2 and all(w.startswith("biso-cosim routes import: warning: ") for w in warning)
    assert "smoothed over 30 m instead of 15 m" in warning[0]
    assert re.search(r"waypoint\[\d+\]\.speed_mps = [\d.]+ m/s.* is never reached", warning[1])


def test_show_and_check_write_their_outputs(capsys, tmp_path):
    rc, out, err = run(capsys, "show", "slalom", "--out", tmp_path / "slalom.png")
    assert rc == 0 and (tmp_path / "slalom.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slalom.png"]


def test_an_imported_route_shows(files, capsys, tmp_path):
    run(capsys, "import", files / "drive.gpx", "--out", tmp_path / "d.toml", "--no-progress")
    rc, out, err = run(capsys, "show", tmp_path / "d.toml", "--out", tmp_path / "d.png")
    assert rc == 0 and Path(tmp_path / "d.png").stat().st_size > 10_000

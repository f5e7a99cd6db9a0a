"""The simulated test motions against BROAD's real trials: what they do to the sensor, and the
ranking of biso_plus, VQF and imufusion on each (issue 23: the simulated comparison should
predict the real ranking).

Part 1, the sensor: on every BROAD trial of DIR (NumPy files of shared/data/broad_dev, or
BROAD's HDF5) `biso_cosim.motions.recording_statistics` against the optical reference, over
the `movement` samples, plus the gyro's bias and the magnetometer's noise at the starting
rest, the gyro against the reference (lag, scale factor) and the lab field's gradient; the
same on each motion of `biso-cosim compare` as `compare.motion_dataset` makes it (the sensor
set-up of the comparison) against its truth (`vibration` while it vibrates).

Part 2, the ranking: BROAD's total RMSE per trial (`biso_cosim.score`) next to the motions'
(`compare.motion_dataset`, seeds `--seeds`), both over the movement only (BROAD's metric: the
comparison's own table counts the motions' rest too); and biso_plus without its online
magnetometer-offset estimate (`estimate_mag_offset=False`).

    python benchmarks/broad_motions.py                    # shared/data/broad_dev, seeds 0,1,2
    python benchmarks/broad_motions.py DIR --seeds 0,1 --no-ranking
    python benchmarks/broad_motions.py --json tests/data/broad_dev_motion_statistics.json

`--json` writes the BROAD figures of part 1 (the numbers the tests compare the motions with).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

from biso_cosim.compare import DEFAULT_MOTIONS, motion_dataset, run_method
from biso_cosim.estimators import make_estimator
from biso_cosim.frames import quat_conjugate, quat_multiply, quat_rotate, quat_to_rotvec
from biso_cosim.motions import recording_statistics
from biso_cosim.score.metrics import trial_rmse_deg
from biso_cosim.score.readers import read_folder

METHODS = ("biso_plus", "vqf", "imufusion")
G_BERLIN = 9.8128  # m/s², BROAD's site (its accelerometer reads 9.82–9.89 m/s² at rest)
LAB_FIELD_TRIALS = ("01", "05", "07")  # undisturbed rotation trials: the lab's field, fitted with the offset
MOTION_OF_TRIAL = {  # BROAD trial (number) → the motion of the comparison that stands for it
    "01": "tumble", "05": "tumble", "07": "fast_tumble", "11": "slow_translation", "15": "translation",
    "21": "shake", "24": "tapping", "27": "vibration", "29": "near_magnet", "33": "magnet",
}


def gyro_against_reference(fs_hz: float, gyro: np.ndarray, q: np.ndarray, moving: np.ndarray):
    """Per gyro axis i, g_i ≈ Σ_j S_ij ω_j − δ_i ω̇_i + b_i by least squares, ω the reference's
    body rate (central differences of q), both low-passed at 15 Hz (samples next to a reference
    dropout skipped): the lag δ (mean of the axes, ms) and the scale-factor and cross-axis
    matrix S."""
    ok = np.all(np.isfinite(q), axis=1)
    i = np.where(ok[:-2] & ok[1:-1] & ok[2:])[0] + 1
    dq = quat_multiply(quat_conjugate(q[i - 1]), q[i + 1])
    dq *= np.sign(dq[:, :1])
    sos = butter(2, 15.0 / (0.5 * fs_hz), output="sos")
    w = sosfiltfilt(sos, quat_to_rotvec(dq) * 0.5 * fs_hz, axis=0)
    g = sosfiltfilt(sos, gyro[i], axis=0)
    keep = moving[i]
    w_dot = np.gradient(w, 1.0 / fs_hz, axis=0)[keep]
    lags, rows = [], []
    for axis in range(3):
        design = np.column_stack([w[keep], -w_dot[:, axis], np.ones(int(keep.sum()))])
        sol = np.linalg.lstsq(design, g[keep, axis], rcond=None)[0]
        rows.append(sol[:3])
        lags.append(sol[3])
    return float(1e3 * np.mean(lags)), np.array(rows)


def field_gradient(fs_hz: float, gyro, accel, mag, q, moving, field_w, g: float = G_BERLIN):
    """The lab field's gradient G (µT/m, ENU) seen by a translated sensor: the field against the
    reference (m − R_refᵀ B − o, its lag τ removed as in `recording_statistics`) turned to ENU,
    regressed on the position (the kinematic acceleration R_ref f − g integrated twice), both
    band-passed to 0.3–4 Hz; returns G and the fraction of the residual it explains."""
    ok = np.all(np.isfinite(q), axis=1)
    first = int(np.argmax(ok))
    hold = np.maximum.accumulate(np.where(ok, np.arange(len(q)), first))  # dropouts: the last attitude
    qf = q[hold] / np.linalg.norm(q[hold], axis=1, keepdims=True)
    st = recording_statistics(fs_hz, gyro, accel, mag, q, moving=moving, field_w=field_w, g=g)
    h = quat_rotate(quat_conjugate(qf), np.tile(np.asarray(field_w, float), (len(q), 1)))
    resid_w = quat_rotate(qf, mag - h - st["mag_offset_ut"] + 1e-3 * st["mag_lag_ms"] * np.cross(h, gyro))
    sos = butter(2, [0.3 / (0.5 * fs_hz), 4.0 / (0.5 * fs_hz)], btype="band", output="sos")
    acc_w = sosfiltfilt(sos, quat_rotate(qf, accel) - [0.0, 0.0, g], axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(len(q), 1.0 / fs_hz)
    w[0] = np.inf
    pos = np.fft.irfft(-np.fft.rfft(acc_w, axis=0) / w[:, None] ** 2, n=len(q), axis=0)
    resid_w = sosfiltfilt(sos, resid_w, axis=0)
    edge = int(2 * fs_hz)  # the filters' start and end
    sel = ok & moving & (np.arange(len(q)) > edge) & (np.arange(len(q)) < len(q) - edge)
    gt = np.linalg.lstsq(pos[sel], resid_w[sel], rcond=None)[0]
    explained = 1.0 - np.sum((resid_w[sel] - pos[sel] @ gt) ** 2) / np.sum(resid_w[sel] ** 2)
    return gt.T, float(explained)


def lab_gradient(real: dict) -> np.ndarray:
    """The mean of the trials' gradients where it explains over 40 % of the field's residual,
    made symmetric and traceless (curl- and divergence-free, as a field without sources)."""
    grads = [np.asarray(st["field_gradient_ut_per_m"]) for st in real["trials"].values()
             if st.get("field_gradient_explained", 0.0) > 0.4]
    mean = np.mean(grads, axis=0)
    sym = 0.5 * (mean + mean.T)
    return sym - np.trace(sym) / 3.0 * np.eye(3)


def broad_statistics(folder: str) -> dict:
    recs = {r.name[:2]: r for r in read_folder(folder)}
    fits = [recording_statistics(recs[n].fs_hz, recs[n].gyro_b, recs[n].accel_b, recs[n].mag_b, recs[n].q_ref,
                                 moving=recs[n].movement, g=G_BERLIN)
            for n in LAB_FIELD_TRIALS if n in recs]
    lab = np.mean([f["field_enu_ut"] for f in fits], axis=0) if fits else None
    out = {"lab_field_enu_ut": None if lab is None else [float(x) for x in lab], "trials": {}}
    for num, r in sorted(recs.items()):
        start = int(np.argmax(r.movement))
        rest = slice(0, int(0.8 * start))  # the starting rest, before the movement is announced
        st = recording_statistics(r.fs_hz, r.gyro_b, r.accel_b, r.mag_b, r.q_ref, moving=r.movement, g=G_BERLIN)
        if lab is not None:
            st_lab = recording_statistics(r.fs_hz, r.gyro_b, r.accel_b, r.mag_b, r.q_ref, moving=r.movement, g=G_BERLIN,
                                          field_w=lab)
            st["mag_offset_lab_field_ut"] = st_lab["mag_offset_ut"]
            st["mag_lag_ms"] = st_lab["mag_lag_ms"]
            # the field where the sensor rests and where it is moved, against the lab's
            st["path_field"], st["rest_field"] = st_lab["path_field"], st_lab["rest_field"]
            grad, explained = field_gradient(r.fs_hz, r.gyro_b, r.accel_b, r.mag_b, r.q_ref, r.movement, lab)
            st["field_gradient_ut_per_m"] = np.round(grad, 3).tolist()
            st["field_gradient_explained"] = explained
            # |m| − |B| over the last 2 s before the movement (trial 29: a magnet beside the resting sensor)
            last = slice(max(0, start - int(2 * r.fs_hz)), start)
            st["mag_norm_before_movement_ut"] = float(np.median(np.linalg.norm(r.mag_b[last], axis=1))
                                                      - np.linalg.norm(lab))
        st["rest_s"] = start / r.fs_hz
        st["rest_gyro_bias_dps"] = [float(x) for x in np.degrees(np.mean(r.gyro_b[rest], axis=0))]
        st["rest_mag_noise_ut"] = [float(x) for x in np.std(r.mag_b[rest], axis=0)]
        st["gyro_lag_ms"], scale = gyro_against_reference(r.fs_hz, r.gyro_b, r.q_ref, r.movement)
        st["gyro_scale_pct"] = [float(x) for x in 100.0 * (np.diag(scale) - 1.0)]
        st["gyro_cross_pct"] = float(100.0 * np.max(np.abs(scale - np.diag(np.diag(scale)))))
        out["trials"][r.name] = st
    return out


def motion_statistics(name: str, seed: int) -> dict:
    d = motion_dataset(name, seed)
    moving = d.info.get("vibrating", d.info["moving"])  # a vibration: while it vibrates
    st = recording_statistics(d.fs_hz, d.gyro_b, d.accel_b, d.mag_b, d.q_true, moving=moving,
                              field_w=d.info["field_enu_ut"])
    rest = ~d.info["moving"]
    if rest.sum() > 10:
        ok = rest & np.all(np.isfinite(d.mag_b), axis=1)
        st["rest_gyro_bias_dps"] = [float(x) for x in np.degrees(np.mean(d.gyro_b[rest], axis=0))]
        st["rest_mag_noise_ut"] = [float(x) for x in np.std(d.mag_b[ok], axis=0)]
    return st


NO_OFFSET = "no_offset"  # biso_plus without its online magnetometer-offset estimate


def total_rmse_deg(q: np.ndarray, d) -> float:
    """BROAD's total RMSE (`biso_cosim.score.metrics`) of a motion dataset over its movement."""
    return trial_rmse_deg(q, d.q_true, d.info["moving"])["total"]


def _row(label: str, values: dict) -> str:
    cells = " ".join(f"{values[m]:9.2f}" for m in (*METHODS, NO_OFFSET))
    ranking = " < ".join(sorted(METHODS, key=values.get))
    return f"{label:34} {cells} {values['biso_plus'] / values['vqf']:7.2f}  {ranking}"


def main() -> None:
    from score import shared_broad_dev  # benchmarks/score.py, beside this script

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", nargs="?", default=shared_broad_dev())
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--json", default=None, help="write the BROAD figures of part 1 to this file")
    ap.add_argument("--no-ranking", action="store_true")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]

    real = broad_statistics(args.dir)
    if args.json:
        real["source"] = ("BROAD (Laidig, Caruso, Cereatti, Seel, Data 6(7):72, 2021; CC BY 4.0), the trials of "
                          f"{Path(args.dir).name}; written by `python benchmarks/broad_motions.py --json`")
        Path(args.json).write_text(json.dumps(real, indent=1) + "\n")
    keys = ("rate_median_dps", "rate_p99_dps", "accel_rms_mps2", "accel_median_hz", "high_accel_rms_mps2",
            "high_gyro_rms_dps", "high_accel_peak_hz", "mag_norm_std_ut", "mag_residual_ut", "mag_lag_ms")
    head = "|ω| med  |ω| p99   |a|  a f50  f>20 Hz  ω>20Hz  peak  σ|m|  m res  m lag   |o|  gyro bias  m noise"
    print(f"BROAD (lab field {np.round(real['lab_field_enu_ut'], 2).tolist()} µT)\n{'':36}{head}")

    def line(label, st, offset_key):
        extra = (f" {np.linalg.norm(st[offset_key]):5.2f}"
                 + (f"  {np.sqrt(np.mean(np.square(st['rest_gyro_bias_dps']))):9.2f}"
                    f"  {np.mean(st['rest_mag_noise_ut']):7.2f}" if "rest_gyro_bias_dps" in st else ""))
        print(f"{label:36}" + " ".join(f"{st[k]:7.2f}" for k in keys) + extra)

    for name, st in real["trials"].items():
        line(name, st, "mag_offset_lab_field_ut")
    print("the gyro against the reference's rate: lag (ms), scale factor − 1 (%), largest cross-axis (%):")
    for name, st in real["trials"].items():
        print(f"  {name:34} lag {st['gyro_lag_ms']:4.1f}  scale {np.round(st['gyro_scale_pct'], 2).tolist()}  "
              f"cross {st['gyro_cross_pct']:.2f}")
    print("the lab field's gradient seen by the translated sensor (0.3–4 Hz), µT/m, and how much of the field's "
          "residual it explains:")
    for name, st in real["trials"].items():
        grad = np.asarray(st["field_gradient_ut_per_m"])
        explained = 100 * st["field_gradient_explained"]
        print(f"  {name:34} |G| {np.linalg.norm(grad, 2):5.1f}  explains {explained:3.0f} %  "
              f"G {np.round(grad, 1).tolist()}")
    print(f"  mean where it explains over 40 %, symmetric and traceless (a field without sources): "
          f"{np.round(lab_gradient(real), 1).tolist()}")
    print(f"motions through compare.motion_dataset (seeds {args.seeds}; |o| against the true field)")
    sim = {(name, seed): motion_statistics(name, seed) for name in DEFAULT_MOTIONS for seed in seeds}
    for (name, seed), st in sim.items():
        line(f"{name} seed {seed}", st, "mag_offset_ut")

    def places(label, st):
        print(f"  {label:34} rest {np.round(st.get('rest_field', [np.nan] * 3), 3).tolist()}  "
              f"moving {np.round(st['path_field'], 3).tolist()}  field's spread in body axes "
              f"{np.round(np.degrees(st['field_spread_rad']), 1).tolist()} °")

    print("the field where the sensor rests and where it moves (norm ratio, azimuth, dip change in ° against the "
          "lab's field; the motions: against the true field), and how far its direction moves in body axes (RMS "
          "along the principal axes):")
    for name, st in real["trials"].items():
        places(name, st)
    for (name, seed), st in sim.items():
        if name in ("translation", "slow_translation"):
            places(f"{name} seed {seed}", st)
    if args.no_ranking:
        return

    from biso_cosim.score import score

    res = score(args.dir, [*METHODS, f"{NO_OFFSET}=biso_plus:estimate_mag_offset=False"], plots=False)
    print(f"\ntotal RMSE over the movement (°){'':5}" + " ".join(f"{m:>9}" for m in (*METHODS, NO_OFFSET))
          + "  bp/VQF  ranking")
    for name, t in res["trials"].items():
        print(_row(name, {m: t["methods"][m]["total_rmse_deg"] for m in (*METHODS, NO_OFFSET)})
              + f"   ({MOTION_OF_TRIAL.get(name[:2], 'no motion')})")
    for name in DEFAULT_MOTIONS:
        per_seed = []
        for seed in seeds:
            d = motion_dataset(name, seed)
            errors = {m: total_rmse_deg(run_method(m, d), d) for m in METHODS}
            q = make_estimator("biso_plus", d.fs_hz, declination_rad=d.declination_rad,
                               estimate_mag_offset=False).update(d.gyro_b, d.accel_b, d.mag_b).q_wb
            per_seed.append({**errors, NO_OFFSET: total_rmse_deg(q, d)})
        mean = {m: float(np.mean([p[m] for p in per_seed])) for m in (*METHODS, NO_OFFSET)}
        ratios = " ".join(f"{p['biso_plus'] / p['vqf']:.2f}" for p in per_seed)
        print(_row(f"{name} (seeds {args.seeds})", mean) + f"   (bp/VQF per seed {ratios})")


if __name__ == "__main__":
    main()

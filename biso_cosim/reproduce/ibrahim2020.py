"""Reproduction of Ibrahim & Lukyanov (2020): GNSS-aided attitude with and without a Kalman filter.

``run(out_dir)`` writes ``report.md``, ``results.json`` and figures, and returns the results
(what ``biso-cosim reproduce ibrahim2020 --out DIR`` does):

1. σ and mean of the pitch, roll and heading errors of ``gnss_complementary`` and
   ``gnss_kalman`` on ``loop600`` and on ``banked_oval`` (sustained turns), next to BISO, its
   baselines and the paper's numbers; variants that isolate the causes: an ideal receiver, a
   perfect magnetometer, the magnetic heading coupling in N, no GNSS at all;
2. the Kalman filter's consistency: normalised innovations (NIS) against χ²₃, the filter's
   σ of roll and pitch against the actual error;
3. behaviour through a GNSS outage (a tunnel on ``loop600``, a 60 s loss on the oval, in its
   turns) with each fall-back policy.

The vehicle, the MPU-9250 and the driver come from :func:`biso_cosim.cosim.run_route`; the
receiver (:class:`biso_cosim.sensors.gnss.GnssReceiver`, consumer profile, 5 Hz) reads the
truth at the sensor's sample times; the GNSS-aided estimators run on the logged samples
(batch = streaming bit for bit, so this is what the loop would give).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from biso_cosim import frames as fr
from biso_cosim.estimators.gnss_aided import (
    GNSS_UNAIDED,
    UPDATE_KINDS,
    GnssComplementaryEstimator,
    GnssComplementaryParams,
    GnssKalmanEstimator,
    GnssKalmanParams,
)
from biso_cosim.metrics import ANGLES, angle_errors_deg

__all__ = ["run", "PAPER"]

PAPER = {
    "no_kf": {"pitch": {"mean_deg": -0.039, "sigma_deg": 0.574}, "roll": {"mean_deg": 0.039, "sigma_deg": 0.576},
              "heading": {"mean_deg": -0.031, "sigma_deg": 0.248}},
    "kf": {"pitch": {"mean_deg": 0.173, "sigma_deg": 0.269}, "roll": {"mean_deg": -0.166, "sigma_deg": 0.247},
           "heading": {"mean_deg": 0.087, "sigma_deg": 0.172}},
    "trajectory": "aircraft, about 800 s at 4.4–5.6 km (Fig. 3); sensors, GNSS and noise levels not stated; MATLAB",
    "signs": "means as printed (OCR); the paper's pitch ϑ is our −pitch, its heading ψ our −heading",
}
"""The paper's results (Figs. 4 and 5 captions)."""

ROUTES = ("loop600", "banked_oval")
SETTLE_S = 10.0
"""Statistics start after this time (the start-up alignment), for every estimator alike."""
BASELINES = ("biso", "biso_plus", "poisson")
CHI2_3 = {"p95": 7.815, "p99": 11.345}


def _outages(route: str, quick: bool) -> tuple[Any, ...]:
    from biso_cosim.sensors.gnss import TimeOutage, ZoneOutage

    if route == "loop600":
        # a 300 m tunnel on the first straight (about 40 s at 8 m/s); quick runs meet it too
        end = 300.0 if quick else 450.0
        return (ZoneOutage((150.0, 0.0), (end, 0.0), 10.0, label="tunnel"),)
    start, length = (15.0, 20.0) if quick else (60.0, 60.0)
    return (TimeOutage(start, start + length, label=f"GNSS lost for {length:g} s in the turns"),)


def _stats(q: np.ndarray, q_true: np.ndarray, t: np.ndarray) -> dict[str, dict[str, float]]:
    err = angle_errors_deg(q, q_true)
    keep = t >= SETTLE_S
    return {a: {"mean_deg": float(err[a][keep].mean()), "sigma_deg": float(err[a][keep].std()),
                "rms_deg": float(np.sqrt(np.mean(err[a][keep] ** 2)))} for a in ANGLES}


def _run_estimator(cls, params, fs, imu, fixes):
    return cls(fs, params).update(imu.gyro_b, imu.accel_b, imu.mag_b, gnss=fixes)


def _consistency(out, q_true: np.ndarray, t: np.ndarray) -> dict[str, Any]:
    u = out.updates[(out.updates["kind"] == UPDATE_KINDS.index("gnss")) & (out.updates["t_s"] >= SETTLE_S)]
    nis = u["nis"]
    err = angle_errors_deg(out.q_wb, q_true)
    keep = t >= SETTLE_S
    sigma = np.degrees(np.sqrt(np.mean(out.tilt_sigma_rad[keep] ** 2, axis=0)))
    return {
        "updates": int(nis.size),
        "nis_mean": float(nis.mean()),
        "nis_expected": 3.0,
        "above_chi2_p95": float(np.mean(nis > CHI2_3["p95"])),
        "above_chi2_p99": float(np.mean(nis > CHI2_3["p99"])),
        "refused_by_gate": int(np.count_nonzero(out.updates["kind"] == UPDATE_KINDS.index("rejected_gate"))),
        "estimated_sigma_deg": {"roll": float(sigma[0]), "pitch": float(sigma[1])},
        "actual_rms_deg": {a: float(np.sqrt(np.mean(err[a][keep] ** 2))) for a in ("roll", "pitch")},
    }


def _outage_run(route_name, res, fs, decl, quick, seed) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    from biso_cosim.sensors.gnss import GnssReceiver

    outages = _outages(route_name, quick)
    rx = GnssReceiver("consumer", seed=seed, rate_hz=5.0, input_rate_hz=fs, site=res.route.site, outages=outages)
    fixes = rx.simulate(res.truth.pos_w, res.truth.vel_w)
    t = res.t_s
    lost = fixes.t_s[~fixes.valid]
    out: dict[str, Any] = {"outages": [repr(o) for o in outages],
                           "lost_s": [float(lost.min()), float(lost.max())] if lost.size else None}
    if not lost.size:
        return out, {}
    during = (t >= lost.min()) & (t <= lost.max() + 5.0)
    after = (t > lost.max() + 5.0) & (t <= lost.max() + 65.0)
    series = {}
    for policy in ("coast", "gravity", "gyro"):
        for label, cls, params in (("gnss_complementary", GnssComplementaryEstimator, GnssComplementaryParams),
                                   ("gnss_kalman", GnssKalmanEstimator, GnssKalmanParams)):
            est = _run_estimator(cls, params(declination_rad=decl, unaided=policy), fs, res.imu, fixes)
            err = angle_errors_deg(est.q_wb, res.truth.q_wb)
            key = f"{label}/{policy}"
            out[key] = {
                "max_abs_during_deg": {a: float(np.abs(err[a][during]).max()) for a in ("roll", "pitch", "heading")},
                "rms_after_deg": ({a: float(np.sqrt(np.mean(err[a][after] ** 2))) for a in ("roll", "pitch")}
                                  if after.any() else None),
                "unaided_s": float(np.count_nonzero(est.flags & GNSS_UNAIDED) / fs),
            }
            if policy == "coast":
                series[label] = err
    series["t"] = t
    series["lost"] = np.array([lost.min(), lost.max()])
    return out, series


def _route(name: str, quick: bool, seed: int) -> tuple[dict[str, Any], dict[str, Any]]:
    from biso_cosim.cosim import run_route
    from biso_cosim.sensors.gnss import GnssReceiver

    res = run_route(name, seed=seed, duration_s=60.0 if quick else None, estimators=BASELINES)
    fs = float(res.sensor["output_rate_hz"])
    decl = math.radians(res.site["declination_deg"])
    t, q_true = res.t_s, res.truth.q_wb
    fixes = {prof: GnssReceiver(prof, seed=seed, rate_hz=5.0, input_rate_hz=fs, site=res.route.site).simulate(
        res.truth.pos_w, res.truth.vel_w) for prof in ("consumer", "ideal")}
    variants = {
        "gnss_complementary": (GnssComplementaryEstimator, GnssComplementaryParams(declination_rad=decl), "consumer"),
        "gnss_kalman": (GnssKalmanEstimator, GnssKalmanParams(declination_rad=decl), "consumer"),
        "gnss_complementary, ideal GNSS": (GnssComplementaryEstimator, GnssComplementaryParams(declination_rad=decl),
                                           "ideal"),
        "gnss_kalman, ideal GNSS": (GnssKalmanEstimator, GnssKalmanParams(declination_rad=decl), "ideal"),
        "gnss_complementary, magnetic coupling": (
            GnssComplementaryEstimator, GnssComplementaryParams(declination_rad=decl, heading_coupling="magnetic"),
            "consumer"),
        "gnss_kalman, magnetic coupling": (
            GnssKalmanEstimator, GnssKalmanParams(declination_rad=decl, heading_coupling="magnetic"), "consumer"),
        "gnss_complementary, no GNSS": (GnssComplementaryEstimator, GnssComplementaryParams(declination_rad=decl), None),
        "gnss_kalman, no GNSS": (GnssKalmanEstimator, GnssKalmanParams(declination_rad=decl), None),
    }
    # the field the vehicle drove through, without the magnetometer's errors (isolates them)
    field = np.asarray(res.site["field_enu_ut"])
    perfect_mag = fr.quat_rotate(fr.quat_conjugate(q_true), np.tile(field, (t.size, 1)))
    for label, cls, params in (("gnss_complementary", GnssComplementaryEstimator, GnssComplementaryParams),
                               ("gnss_kalman", GnssKalmanEstimator, GnssKalmanParams)):
        variants[f"{label}, perfect magnetometer"] = (cls, params(declination_rad=decl), "consumer")
    stats: dict[str, Any] = {}
    series: dict[str, Any] = {"t": t}
    kalman = None
    for key, (cls, params, prof) in variants.items():
        imu = res.imu
        if key.endswith("perfect magnetometer"):
            imu = dataclasses.replace(res.imu, mag_b=perfect_mag)
        est = _run_estimator(cls, params, fs, imu, fixes[prof] if prof else None)
        stats[key] = _stats(est.q_wb, q_true, t)
        if key in ("gnss_complementary", "gnss_kalman"):
            series[key] = angle_errors_deg(est.q_wb, q_true)
        if key == "gnss_kalman":
            kalman = est
            series["sigma"] = np.degrees(est.tilt_sigma_rad)
    for key in BASELINES:
        stats[key] = _stats(res.estimates[key][0], q_true, t)
        series[key] = res.errors(key)
    outage, outage_series = _outage_run(name, res, fs, decl, quick, seed)
    site = dict(res.site, horizontal_ut=float(np.hypot(*res.site["field_enu_ut"][:2])))
    summary = {
        "route": res.route.summary(),
        "duration_s": res.duration_s,
        "completed": res.completed,
        "sensor": res.sensor,
        "site": site,
        "receiver": {"profile": "consumer", "rate_hz": 5.0, "fixes": len(fixes["consumer"])},
        "stats": stats,
        "consistency": _consistency(kalman, q_true, t),
        "final_drift_estimate_deg_s": np.degrees(kalman.gyro_bias_b[-1]).tolist(),
        "outage": outage,
    }
    return summary, {"errors": series, "outage": outage_series}


# --------------------------------------------------------------------------------------
# figures and report
# --------------------------------------------------------------------------------------


def _plot_errors(name: str, series: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = series["t"]
    fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True, layout="constrained")
    for ax, angle in zip(axes, ("roll", "pitch", "heading")):
        for key, color in (("biso", "0.6"), ("gnss_complementary", "C1"), ("gnss_kalman", "C0")):
            ax.plot(t, series[key][angle], color=color, lw=0.8, label=key)
        if angle != "heading":
            s = series["sigma"][:, 0 if angle == "roll" else 1]
            ax.fill_between(t, -s, s, color="C0", alpha=0.15, lw=0, label="gnss_kalman ±σ")
        ax.set_ylim(-2.0, 2.0)
        ax.set_ylabel(f"{angle} error (°)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{name}: attitude errors (BISO clipped at ±2°)")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_outage(name: str, series: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, lost = series["t"], series["lost"]
    window = (t > lost[0] - 30.0) & (t < lost[1] + 60.0)
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True, layout="constrained")
    for ax, angle in zip(axes, ("roll", "pitch")):
        for key, color in (("gnss_complementary", "C1"), ("gnss_kalman", "C0")):
            ax.plot(t[window], series[key][angle][window], color=color, lw=0.8, label=key)
        ax.axvspan(lost[0], lost[1], color="0.85", label="no valid fix")
        ax.set_ylabel(f"{angle} error (°)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{name}: through a GNSS outage (fall-back 'coast')")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _f(x: float | None, nd: int = 3) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{nd}f}"


def _table(rows: list[tuple[str, dict[str, Any]]]) -> list[str]:
    lines = ["| estimator | pitch mean | pitch σ | roll mean | roll σ | heading mean | heading σ |",
             "|---|---|---|---|---|---|---|"]
    for label, s in rows:
        lines.append(f"| {label} | " + " | ".join(f"{_f(s[a]['mean_deg'])} | {_f(s[a]['sigma_deg'])}"
                                               for a in ("pitch", "roll", "heading")) + " |")
    return lines


def _sigma_range(r: dict[str, Any], keys: tuple[str, ...], angles: tuple[str, ...]) -> tuple[float, float]:
    values = [r["routes"][n]["stats"][k][a]["sigma_deg"] for n in ROUTES for k in keys for a in angles]
    return min(values), max(values)


def _against_the_paper(r: dict[str, Any]) -> list[str]:
    """The comparison, with the measured figures drawn from the results."""
    p = PAPER
    ours = ("gnss_complementary", "gnss_kalman")
    tilt, head = _sigma_range(r, ours, ("roll", "pitch")), _sigma_range(r, ours, ("heading",))
    plus_tilt, plus_head = _sigma_range(r, ("biso_plus",), ("roll", "pitch")), _sigma_range(r, ("biso_plus",), ("heading",))
    biso_tilt = _sigma_range(r, ("biso",), ("roll", "pitch"))
    kf_better = [n for n in ROUTES if all(r["routes"][n]["stats"]["gnss_kalman"][a]["sigma_deg"]
                                          <= r["routes"][n]["stats"]["gnss_complementary"][a]["sigma_deg"]
                                          for a in ("roll", "pitch"))]
    ideal = _sigma_range(r, tuple(f"{k}, ideal GNSS" for k in ours), ("roll", "pitch"))
    coupled = _sigma_range(r, ("gnss_complementary, magnetic coupling",), ("roll", "pitch"))
    perfect = tuple(f"{k}, perfect magnetometer" for k in ours)
    pm_tilt, pm_head = _sigma_range(r, perfect, ("roll", "pitch")), _sigma_range(r, perfect, ("heading",))
    coast = [max(v["max_abs_during_deg"]["roll"], v["max_abs_during_deg"]["pitch"])
             for n in ROUTES for k, v in r["routes"][n]["outage"].items() if k == "gnss_kalman/coast"]
    return [
        "## Against the paper", "",
        f"The paper's numbers come from an {p['trajectory']}. What differs here, and why:", "",
        f"* **Tilt.** Both variants hold roll and pitch to a σ of {tilt[0]:.2f}–{tilt[1]:.2f}° on the car, against "
        "the paper's 0.25–0.58°. The correction compares GNSS and accelerometer over 1 s windows between fixes "
        "(velocity differences, never differentiated position), in which the receiver's velocity noise nearly "
        f"cancels: with an ideal receiver the σ is still {ideal[0]:.2f}–{ideal[1]:.2f}°. What remains is the "
        "calibrated MPU-9250 (residual accelerometer bias, indistinguishable from tilt; gyro drift over the "
        "loop's memory) and the heading error that N0 = e_Up × f couples into tilt under horizontal acceleration. "
        "The paper's sensors and noise levels are not stated.",
        "* **Kalman vs no Kalman.** As in the paper, the Kalman variant is the better one on tilt "
        f"({'on both routes' if len(kf_better) == len(ROUTES) else 'on ' + ', '.join(kf_better) or 'on neither route'}"
        "): it estimates the roll and pitch gyro drifts and weighs the windows by their noise. Its heading is the "
        "same channel (5), (6) as the complementary variant's.",
        f"* **Heading.** Our heading σ is {head[0]:.2f}–{head[1]:.2f}°, above the paper's 0.17–0.25°. It follows the "
        "AK8963 with the calibrated profile's residual offsets (up to 1 µT per axis) in a horizontal field of "
        f"{r['routes'][ROUTES[0]]['site']['horizontal_ut']:.1f} µT: each µT of offset is up to 3° of heading, "
        "changing with heading (the errors oscillate once per lap of the oval). T2 = 10 s trades it against the vertical gyro drift (the heading mean). With a "
        f"perfect magnetometer the heading σ falls to {pm_head[0]:.2f}–{pm_head[1]:.2f}°, below the paper's, and "
        f"the tilt σ to {pm_tilt[0]:.2f}–{pm_tilt[1]:.2f}°: the heading error is also what limits the tilt in turns.",
        "* **Means** are set by the constant errors (accelerometer bias for tilt, magnetometer offsets for "
        "heading), drawn per seed; the paper's ±0.04–0.17° are one trajectory's and do not transfer.",
        f"* **BISO** is referenced to the accelerometer alone: sustained accelerations tilt it (tilt σ up to "
        f"{biso_tilt[1]:.1f}°, the oval's 0.38 g turns most). **biso_plus** (gyro-bias estimation, a low-pass of the "
        "specific force in a quasi-inertial frame, gating, online magnetometer-offset estimation) reaches a tilt σ "
        f"of {plus_tilt[0]:.2f}–{plus_tilt[1]:.2f}° without GNSS on these routes and a heading σ of "
        f"{plus_head[0]:.2f}–{plus_head[1]:.2f}°: the offset estimation is what our heading channel (the paper's, "
        "with fixed hard and soft iron) lacks.",
        "* **Magnetic coupling in N** (N + N0·[P1 P2]) assumes the heading has settled on the tilt error (t ≫ T2). "
        "With T1 = 3 s < T2 = 10 s that fails and the complementary variant runs away in sustained turns "
        f"(tilt σ up to {coupled[1]:.1f}°); the default leaves it out and adds the heading error's variance to R.",
        "* **Outages.** Coasting on the gyro (the default fall-back) keeps the Kalman variant's tilt within "
        f"{max(coast) if coast else float('nan'):.2f}° through the outages, because the filter has estimated the "
        "drifts; the gravity reference leans into the turns; the first fixes afterwards pull the error back.",
        ""]


def _report(r: dict[str, Any]) -> str:
    p = PAPER
    lines = ["# Ibrahim & Lukyanov (2020): reproduction", "",
             "GNSS-aided attitude (`biso_cosim.estimators.gnss_aided`, decisions in docs/gnss.md) on the simulated "
             "car with the virtual MPU-9250 (profile `" + r["routes"][ROUTES[0]]["sensor"]["profile"] + "`) and a "
             "consumer GNSS receiver (u-blox M8 class, 5 Hz, 0.1 s latency). Errors in degrees, estimate minus "
             f"truth, statistics after {SETTLE_S:g} s; σ is the standard deviation about the mean. Our pitch is "
             "ISO 8855 (nose down positive): the paper's ϑ is −pitch, so its means compare with ours with the "
             "sign flipped. Numbers from `results.json`.", ""]
    for name in ROUTES:
        rr = r["routes"][name]
        st = rr["stats"]
        lines += [f"## {name}: {rr['route']['description']}", "",
                  f"{rr['duration_s']:.0f} s simulated, route {'completed' if rr['completed'] else 'not completed'}, "
                  f"{rr['receiver']['fixes']} fixes. ![]({name}_errors.png)", ""]
        rows = [(k, st[k]) for k in ("gnss_complementary", "gnss_kalman")]
        rows += [(f"paper, {'no KF' if k == 'no_kf' else 'KF'}", p[k]) for k in ("no_kf", "kf")]
        rows += [(k, st[k]) for k in BASELINES]
        rows += [(k, st[k]) for k in st if "," in k]
        lines += _table(rows) + [""]
        c = rr["consistency"]
        lines += [f"**Consistency of `gnss_kalman`** ({c['updates']} GNSS windows): mean NIS {c['nis_mean']:.2f} "
                  f"(χ²₃: 3), above the χ²₃ 95 % point {100 * c['above_chi2_p95']:.1f} % (5 % expected), above "
                  f"99 % {100 * c['above_chi2_p99']:.1f} %; refused by the gate {c['refused_by_gate']}. Filter σ "
                  f"roll {c['estimated_sigma_deg']['roll']:.3f}°, pitch {c['estimated_sigma_deg']['pitch']:.3f}° "
                  f"against actual RMS {c['actual_rms_deg']['roll']:.3f}°, {c['actual_rms_deg']['pitch']:.3f}°. "
                  f"Drift estimate at the end {np.round(rr['final_drift_estimate_deg_s'], 4).tolist()} °/s "
                  "(body x, y, z).", ""]
        o = rr["outage"]
        if o.get("lost_s"):
            lines += [f"**Outage**: {', '.join(o['outages'])}; no valid fix from {o['lost_s'][0]:.1f} s to "
                      f"{o['lost_s'][1]:.1f} s. ![]({name}_outage.png)", "",
                      "| estimator / fall-back | max roll error during | max pitch error during | max heading error "
                      "during | roll RMS 60 s after | pitch RMS 60 s after | flagged unaided (s) |",
                      "|---|---|---|---|---|---|---|"]
            for key, v in o.items():
                if "/" not in key:
                    continue
                after = v["rms_after_deg"] or {}
                lines.append(f"| {key} | {_f(v['max_abs_during_deg']['roll'])} | {_f(v['max_abs_during_deg']['pitch'])}"
                             f" | {_f(v['max_abs_during_deg']['heading'])} | {_f(after.get('roll'))} | "
                             f"{_f(after.get('pitch'))} | {v['unaided_s']:.1f} |")
            lines.append("")
    lines += _against_the_paper(r)
    return "\n".join(lines)


def run(out_dir: str | Path, *, quick: bool = False, seed: int = 0) -> dict[str, Any]:
    """Reproduce the paper's claims into ``out_dir`` (``report.md``, ``results.json``, figures).

    ``quick``: 60 s of each route and shorter outages (a smoke test, minutes → seconds).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"paper": PAPER, "quick": quick, "seed": seed, "settle_s": SETTLE_S, "routes": {}}
    for name in ROUTES:
        summary, series = _route(name, quick, seed)
        results["routes"][name] = summary
        _plot_errors(name, series["errors"], out / f"{name}_errors.png")
        if series["outage"]:
            _plot_outage(name, series["outage"], out / f"{name}_outage.png")
    (out / "results.json").write_text(json.dumps(results, indent=2, default=float))
    (out / "report.md").write_text(_report(results))
    return results

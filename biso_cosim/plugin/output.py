"""What one call of the plug-in returns: the samples the chip latched, the estimates after
each of them and the truth at their instants; in the host's conventions on demand.

The package-frame arrays (``samples``, ``q_true_wb``, ``estimates[label].estimate``) are what
the plug-in computed; the host-frame views (``gyro_b``, ``q_wb`` ...) are converted when read
(each is a new array), so a host that reads only the latest estimate pays for nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from biso_cosim.estimators import Estimate
from biso_cosim.metrics import angle_errors_deg
from biso_cosim.plugin.adapter import HostFrames
from biso_cosim.sensors import ImuSamples, RawSamples

__all__ = ["PluginOutput", "EstimateOutput"]


@dataclass(frozen=True, eq=False)
class EstimateOutput:
    """One estimator's attitude after each sample of a call, and its error.

    Attributes:
        estimate: the estimator's own ``Estimate`` (package frames: ``q_wb`` ENU ← FLU,
            scalar first; ``flags``; ``gyro_bias_b`` FLU or None).
        q_true_wb: (k, 4) the truth at the samples' instants, package frames.
        frames: the host's conventions.
    """

    estimate: Estimate
    q_true_wb: np.ndarray
    frames: HostFrames

    def __len__(self) -> int:
        return self.estimate.q_wb.shape[0]

    @property
    def q_wb(self) -> np.ndarray:
        """(k, 4) estimated attitude, host conventions (world ← body, host quaternion order)."""
        return self.frames.attitude_from_package(self.estimate.q_wb)

    @property
    def flags(self) -> np.ndarray:
        """(k,) the estimator's flag bits (``biso_cosim.estimators.flags``)."""
        return self.estimate.flags

    @property
    def gyro_bias_b(self) -> np.ndarray | None:
        """(k, 3) estimated gyro bias in rad/s, host body axes (None if not estimated)."""
        bias = self.estimate.gyro_bias_b
        return None if bias is None else self.frames.flu_to_body(bias)

    @property
    def errors_deg(self) -> dict[str, np.ndarray]:
        """Estimate minus truth at each sample, degrees: roll, pitch, compass heading (each
        wrapped to (−180, 180]) and the total rotation angle, as
        ``biso_cosim.metrics.angle_errors_deg`` defines them (ISO 8855 angles of the vehicle:
        the same whatever the host's conventions)."""
        if len(self) == 0:
            empty = np.empty(0)
            return {"roll": empty, "pitch": empty, "heading": empty, "total": empty.copy()}
        return angle_errors_deg(self.estimate.q_wb, self.q_true_wb)


@dataclass(frozen=True, eq=False)
class PluginOutput:
    """The samples latched since the previous call (k of them, often 0) and what followed.

    Attributes:
        t_s: (k,) the host's time of each sample (the instant the chip latched it).
        samples: the chip's ``ImuSamples`` in package frames (FLU body axes), time stamps on
            the chip's own axis (0 at the first tick).
        q_true_wb: (k, 4) the host's attitude at each sample's instant, package frames
            (nlerp between the ticks around it).
        estimates: label → ``EstimateOutput``.
        frames: the host's conventions, for the host-frame views.
    """

    t_s: np.ndarray
    samples: ImuSamples
    q_true_wb: np.ndarray
    estimates: dict[str, EstimateOutput]
    frames: HostFrames

    def __len__(self) -> int:
        return self.t_s.shape[0]

    @property
    def gyro_b(self) -> np.ndarray:
        """(k, 3) angular rate readings, rad/s, host body axes."""
        return self.frames.flu_to_body(self.samples.gyro_b)

    @property
    def accel_b(self) -> np.ndarray:
        """(k, 3) specific force readings, m/s² (+g up at rest), host body axes."""
        return self.frames.flu_to_body(self.samples.accel_b)

    @property
    def mag_b(self) -> np.ndarray:
        """(k, 3) magnetometer readings, µT, host body axes (held between AK8963 updates)."""
        return self.frames.flu_to_body(self.samples.mag_b)

    @property
    def temperature_c(self) -> np.ndarray:
        return self.samples.temperature_c

    @property
    def flags(self) -> np.ndarray:
        """(k,) the chip's flag bits (``biso_cosim.sensors.ImuFlag``)."""
        return self.samples.flags

    @property
    def raw(self) -> RawSamples:
        """The register values, chip axes (the same in every host convention)."""
        return self.samples.raw

    @property
    def q_true(self) -> np.ndarray:
        """(k, 4) the truth at the samples' instants, host conventions."""
        return self.frames.attitude_from_package(self.q_true_wb)

    def latest(self, label: str | None = None) -> np.ndarray | None:
        """The estimated attitude after the last sample of this call (host conventions), or
        None when the call latched no sample. ``label``: which estimator (default the first)."""
        if len(self) == 0:
            return None
        est = self.estimates[label if label is not None else next(iter(self.estimates))]
        return self.frames.attitude_from_package(est.estimate.q_wb[-1])

    def copy(self) -> "PluginOutput":
        """This output in arrays of its own (to keep it past the next call of a plug-in with
        ``reuse_outputs``)."""
        return PluginOutput.concatenate([self])

    @staticmethod
    def concatenate(parts: "list[PluginOutput]") -> "PluginOutput":
        """One output from consecutive ones (a whole run from its calls), in arrays of its own."""
        if not parts:
            raise ValueError("parts must hold at least one PluginOutput")
        first = parts[0]
        q_true = np.concatenate([p.q_true_wb for p in parts])
        estimates: dict[str, EstimateOutput] = {}
        for label, est in first.estimates.items():
            chunks = [p.estimates[label].estimate for p in parts]
            bias = None if est.estimate.gyro_bias_b is None else np.concatenate([c.gyro_bias_b for c in chunks])
            merged = Estimate(np.concatenate([c.q_wb for c in chunks]), np.concatenate([c.flags for c in chunks]), bias)
            estimates[label] = EstimateOutput(merged, q_true, first.frames)
        return PluginOutput(np.concatenate([p.t_s for p in parts]), ImuSamples.concatenate([p.samples for p in parts]),
                            q_true, estimates, first.frames)


def empty_estimate(estimates_bias: bool) -> Estimate:
    return Estimate(np.empty((0, 4)), np.empty(0, dtype=np.int64), np.empty((0, 3)) if estimates_bias else None)

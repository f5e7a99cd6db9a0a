"""Example: scripted driving-route tests of your own estimator (the test suite runs this file).

Copy it into your project's tests, replace ``TiltHeadingFilter`` by your estimator, and set
the bounds your application needs. Each test drives a route from the library (or your own
route file) with the virtual MPU-9250 and your estimator in the loop, then asserts errors.
"""

import math

import numpy as np
import pytest

from biso_cosim.frames import quat_from_rotvec, quat_multiply, quat_normalize, quat_rotate
from biso_cosim.testing import drive


class TiltHeadingFilter:
    """A user's estimator, written plainly: gyro integration with small corrections of the
    tilt toward the accelerometer's "up" and of the heading toward the magnetometer.

    The co-simulation calls ``update`` once per control period with the k new samples (SI,
    body axes x forward, y left, z up) and expects the k attitudes ``q_wb`` back.
    """

    def __init__(self, fs_hz: float = 200.0, tilt_gain: float = 0.02, heading_gain: float = 0.02,
                 declination_rad: float = math.radians(11.26)):
        self.dt = 1.0 / fs_hz
        self.tilt_gain = tilt_gain
        self.heading_gain = heading_gain
        self.declination_rad = declination_rad
        self.q = None

    def reset(self):
        self.q = None

    def update(self, gyro_b, accel_b, mag_b):
        out = np.empty((gyro_b.shape[0], 4))
        for i, (w, f, m) in enumerate(zip(gyro_b, accel_b, mag_b)):
            if self.q is None:  # start level, heading from the magnetometer (yaw CCW from East)
                yaw = math.pi / 2 - self.declination_rad - math.atan2(m[1], m[0])
                self.q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
            up_b = f / np.linalg.norm(f)
            up_est = quat_rotate(np.array([self.q[0], -self.q[1], -self.q[2], -self.q[3]]), [0.0, 0.0, 1.0])
            tilt = self.tilt_gain * np.cross(up_b, up_est)  # Mahony: turn the estimated up toward the measured
            m_w = quat_rotate(self.q, m)
            heading_err = math.atan2(m_w[0], m_w[1]) - self.declination_rad  # field azimuth minus its true one
            heading_err = (heading_err + math.pi) % (2 * math.pi) - math.pi
            correction_b = quat_rotate(np.array([self.q[0], -self.q[1], -self.q[2], -self.q[3]]),
                                       [0.0, 0.0, self.heading_gain * heading_err])
            self.q = quat_normalize(quat_multiply(self.q, quat_from_rotvec((w + tilt + correction_b) * self.dt)))
            out[i] = self.q
        return out


def test_my_filter_keeps_tilt_on_the_hill():
    run = drive("hill_climb", estimator=TiltHeadingFilter(), seed=0, duration_s=60.0)
    # 15 % grades and the acceleration of climbing: within 2° once it has settled (5 s)
    run.assert_max_error(roll=2.0, pitch=2.0, after_s=5.0)


def test_my_filter_heading_in_the_figure_eight():
    run = drive("figure8", estimator=TiltHeadingFilter(), seed=0)
    run.assert_rms_error(heading=4.0, after_s=5.0)


@pytest.mark.biso_route("slalom", estimator="biso", seed=1)
def test_biso_in_the_slalom(route_run):
    route_run.assert_completed(max_cross_track_m=1.0)
    # the faithful BISO follows the accelerometer (DC gain 1, docs/design.md §5): at 0.35 g of
    # lateral acceleration it leans by up to ~15°; a test documents such a property too
    route_run.assert_max_error(roll=16.0)

"""Build the MuJoCo model of a route: the reference car (``car.xml``) on the route's terrain.

The car is an MJCF file written for this project (see its header for the parameters); the
ground is a plane plus height-field patches sampled from the route's analytic terrain
(:mod:`biso_cosim.vehicle.terrain`), added with ``mujoco.MjSpec``. Names of the joints,
actuators and sensors that the rest of the package uses are collected in :class:`CarIndex`.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

from biso_cosim.vehicle.terrain import HeightField, Terrain
from biso_cosim.vehicle.tyres import DEFAULT_TYRE_MODEL, TYRE_MODELS

__all__ = ["CAR_XML", "CarIndex", "build_model", "car_spec", "vehicle_parameters"]

CAR_XML = resources.files("biso_cosim.vehicle").joinpath("car.xml")

# A height field's solid base below its lowest point, m (MuJoCo needs a positive base).
_HFIELD_BASE_M = 1.0
# Dry asphalt: sliding, torsional and rolling friction (MuJoCo uses the larger of the pair).
_GROUND_FRICTION = [1.0, 0.005, 0.0001]


def car_spec() -> mujoco.MjSpec:
    """The car alone, as an editable MjSpec."""
    return mujoco.MjSpec.from_string(CAR_XML.read_text())


def build_model(terrain: Terrain, *, timestep_s: float = 0.001, history_steps: int = 0,
                tyres: str = DEFAULT_TYRE_MODEL, tyre_params=None, chassis_params=None,
                surface: str | float = "dry") -> tuple[mujoco.MjModel, list[HeightField]]:
    """Compile the car on ``terrain``: the ground plane plus one height field per patch.

    ``tyres``: ``"magic_formula"`` (the default, ``tyres.DEFAULT_TYRE_MODEL``: slip-based tyre
    forces of ``vehicle.tyres``, a C engine plugin, with
    ``tyre_params``, default ``tyres.TYRES``, on a road of friction ``surface``: a name of
    ``tyres.SURFACES`` or a scale; only with the magic_formula tyres; and ``chassis_params``,
    default ``tyres.CHASSIS``: the brakes' torque and balance, the ABS, the compliance steer;
    the terrain's surface patches, ``Terrain.surfaces``, set the friction where they lie) or
    ``"coulomb"`` (MuJoCo's Coulomb friction on the sphere wheels: the car before issue 26).

    Returns the model and the sampled patches. The magnetic field of the model stays zero:
    the vehicle's magnetic environment is modelled by :mod:`biso_cosim.sensors`. With
    ``history_steps`` every sensor keeps its values of that many steps in MuJoCo's history
    buffer (``MjData.history``; no delay, so ``sensordata`` is unchanged).
    """
    if not timestep_s > 0.0:
        raise ValueError(f"timestep_s must be > 0, got {timestep_s}")
    if isinstance(history_steps, bool) or not isinstance(history_steps, int) or history_steps < 0:
        raise ValueError(f"history_steps must be an int >= 0, got {history_steps!r}")
    if tyres not in TYRE_MODELS:
        raise ValueError(f"tyres must be 'coulomb' or 'magic_formula', got {tyres!r}")
    if tyres == "coulomb" and (tyre_params is not None or chassis_params is not None or surface != "dry"):
        raise ValueError("tyre_params, chassis_params and surface apply to tyres='magic_formula' only")
    if tyres == "coulomb" and terrain.surfaces:
        raise ValueError("the terrain's surface patches apply to tyres='magic_formula' only")
    spec = car_spec()
    ground_friction = _GROUND_FRICTION
    if tyres == "magic_formula":
        from biso_cosim.vehicle.tyres import add_tyre_plugin, surface_friction

        ground_friction = [surface_friction(surface), *_GROUND_FRICTION[1:]]
        add_tyre_plugin(spec, tyre_params, chassis_params, surfaces=terrain.surfaces)
    spec.option.timestep = timestep_s
    for sensor in spec.sensors:
        sensor.nsample = history_steps
    # the collision plane is hidden (group 3); what is drawn is a plane 2 cm below it, so that
    # the height-field patches, whose borders lie at z = 0, do not z-fight with the ground
    spec.worldbody.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0],
                            material="ground", friction=ground_friction, group=3)
    spec.worldbody.add_geom(name="ground_visual", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0],
                            pos=[0.0, 0.0, -0.02], material="ground", contype=0, conaffinity=0, group=0)
    patches = terrain.patches()
    for k, patch in enumerate(patches):
        # MuJoCo scales normalised data by the elevation size: keep it positive.
        elevation = max(float(patch.heights_m.max()), 1e-3)
        normalised = (patch.heights_m / elevation).astype(np.float32).ravel()
        rx, ry = patch.half_size_m
        spec.add_hfield(name=f"terrain{k}", nrow=patch.nrow, ncol=patch.ncol,
                        size=[rx, ry, elevation, _HFIELD_BASE_M], userdata=normalised)
        cx, cy = patch.center_m
        spec.worldbody.add_geom(name=f"terrain{k}", type=mujoco.mjtGeom.mjGEOM_HFIELD,
                                hfieldname=f"terrain{k}", pos=[cx, cy, 0.0], material="ground",
                                friction=ground_friction)
    return spec.compile(), patches


@dataclass(frozen=True)
class CarIndex:
    """Addresses in a compiled car model of everything the co-simulation reads or drives."""

    # actuators
    steer: int
    drive: int
    resistance: int
    brakes: np.ndarray
    # sensordata slices
    gyro: slice
    accel: slice
    quat: slice
    pos: slice
    vel_w: slice
    rear_axle_pos: slice
    rear_axle_vel_b: slice
    wheel_rates: slice
    steering_angle: slice
    # geometry
    imu_site: int
    imu_pos_b: np.ndarray  # IMU site in the chassis frame, m
    rear_axle_b: np.ndarray
    wheelbase_m: float
    track_m: float
    wheel_radius_m: float
    chassis_body: int

    @staticmethod
    def of(model: mujoco.MjModel) -> "CarIndex":
        def sensor(name: str) -> slice:
            i = model.sensor(name).id
            adr, dim = int(model.sensor_adr[i]), int(model.sensor_dim[i])
            return slice(adr, adr + dim)

        spins = [sensor(f"{w}_spin_rate") for w in ("fl", "fr", "rl", "rr")]
        assert all(s.start == spins[0].start + k for k, s in enumerate(spins))
        chassis = model.body("chassis").id
        front = model.body("fl_corner").pos
        rear = model.body("rl_corner").pos
        return CarIndex(
            steer=model.actuator("steer").id,
            drive=model.actuator("drive").id,
            resistance=model.actuator("resistance").id,
            brakes=np.array([model.actuator(f"brake_{w}").id for w in ("fl", "fr", "rl", "rr")]),
            gyro=sensor("imu_gyro"),
            accel=sensor("imu_accel"),
            quat=sensor("imu_quat"),
            pos=sensor("imu_pos"),
            vel_w=sensor("imu_vel"),
            rear_axle_pos=sensor("rear_axle_pos"),
            rear_axle_vel_b=sensor("rear_axle_vel"),
            wheel_rates=slice(spins[0].start, spins[-1].stop),
            steering_angle=sensor("steering_angle"),
            imu_site=model.site("imu").id,
            imu_pos_b=model.site("imu").pos.copy(),
            rear_axle_b=model.site("rear_axle").pos.copy(),
            wheelbase_m=float(front[0] - rear[0]),
            track_m=float(front[1] - model.body("fr_corner").pos[1]),
            wheel_radius_m=float(model.geom("fl_tyre").size[0]),
            chassis_body=chassis,
        )


def vehicle_parameters(model: mujoco.MjModel | None = None, drivetrain=None) -> dict[str, float]:
    """The car's main parameters, read from the compiled model (the MJCF is the one source
    of its geometry, masses and brakes) and its drivetrain (``vehicle.drivetrain.DRIVETRAIN``
    unless given: the one source of its engine and driving resistances)."""
    from biso_cosim.vehicle.drivetrain import DRIVETRAIN

    drivetrain = DRIVETRAIN if drivetrain is None else drivetrain
    if model is None:
        model = car_spec().compile()
    idx = CarIndex.of(model)
    chassis = idx.chassis_body
    total = float(model.body_subtreemass[chassis])
    # sprung: everything above the springs (the chassis and the steering column)
    sprung = float(model.body_mass[chassis] + model.body_mass[model.body("steering").id])
    # the model's initial pose is the static one (zero suspension travel under the springs'
    # preload): the whole car's centre of mass there
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    front_axle_x = float(model.body("fl_corner").pos[0])
    susp = {name: model.joint(f"{name}_susp") for name in ("fl", "rl")}
    return {
        "total_mass_kg": total,
        "sprung_mass_kg": sprung,
        "wheelbase_m": idx.wheelbase_m,
        "track_m": idx.track_m,
        "cg_behind_front_axle_m": front_axle_x,
        "sprung_cg_height_m": float(model.body("chassis").pos[2]),
        "cg_height_m": float(data.subtree_com[chassis][2]),
        "wheel_radius_m": idx.wheel_radius_m,
        "spring_front_n_per_m": float(model.jnt_stiffness[susp["fl"].id]),
        "spring_rear_n_per_m": float(model.jnt_stiffness[susp["rl"].id]),
        "damper_front_ns_per_m": float(model.dof_damping[model.jnt_dofadr[susp["fl"].id]]),
        "damper_rear_ns_per_m": float(model.dof_damping[model.jnt_dofadr[susp["rl"].id]]),
        "max_steer_rad": float(model.actuator_ctrlrange[idx.steer][1]),
        "max_drive_torque_nm": drivetrain.peak_wheel_torque_nm,
        "wheel_damping_nms_per_rad": float(model.dof_damping[model.jnt_dofadr[model.joint("rl_spin").id]]),
        # the four wheels' mean (the slip-tyre car's brakes differ front and rear: tyres.ChassisParams)
        "max_brake_torque_per_wheel_nm": float(np.mean(model.actuator_forcerange[idx.brakes, 1])),
        # a damper actuator's force is gainprm[2]·ctrl·velocity with gainprm[2] = -kv
        "brake_kv_nms_per_rad": float(-np.mean(model.actuator_gainprm[idx.brakes, 2])),
    }

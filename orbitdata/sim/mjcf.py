"""Build the MuJoCo model (MJCF XML) of one scenario."""

from __future__ import annotations

from orbitdata.scenario.spec import Scenario
from orbitdata.sim.config import SimConfig
from orbitdata.sim.thrusters import thruster_layout

BODY = "cubesat"
HULL = "hull"
CAMERA = "onboard"
OBSTACLE_PREFIX = "obstacle"
DEBRIS_PREFIX = "debris"  # the dynamic tier's mocap bodies, one per obstacle geom
ONBOARD_LIGHT = "onboard"
# Tumble must show: debris wears a checker texture (cube-mapped, so spheres show it too).
DEBRIS_ASSETS = """
    <texture name="debris" type="cube" builtin="checker" rgb1="1 1 1" rgb2="0.45 0.45 0.45" width="16" height="16"/>
    <material name="debris" texture="debris" specular="0.1" shininess="0.1" reflectance="0"/>"""


def _fmt(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _z_to(direction) -> str:
    """MJCF ``zaxis`` attribute: orient a site so its z axis is ``direction``."""
    return _fmt(direction)


def build_mjcf(scn: Scenario, cfg: SimConfig) -> str:
    """MJCF for the CubeSat, its thrusters and camera, the obstacles and the light.

    Zero gravity, no air; obstacles are static world geoms. Each thruster is a motor on a
    site whose z axis is its force direction, so ``ctrl`` in [0, 1] is normalised thrust.
    In the dynamic tier each obstacle is the geom of a mocap body that the simulator moves
    along its analytic motion, textured so that its tumble shows; the centre of mass sits at
    the drawn offset and a spotlight beside the camera lights the scene (alone, in eclipse).
    The CubeSat collides with obstacles, obstacles never with each other (contype/conaffinity).
    """
    sat, cam = cfg.cubesat, cfg.camera
    size = cam.image_size
    h = sat.half_size
    light = scn.lighting
    diffuse = _fmt([light.sun_intensity] * 3)
    ambient = _fmt([light.ambient] * 3)
    positions, directions = thruster_layout(sat)
    sites = "\n".join(
        f'      <site name="thruster{i}" pos="{_fmt(p)}" zaxis="{_z_to(d)}" size="0.004" rgba="0.9 0.3 0.1 1"/>'
        for i, (p, d) in enumerate(zip(positions, directions))
    )
    motors = "\n".join(
        f'    <motor name="thruster{i}" site="thruster{i}" gear="0 0 {sat.max_thrust:.9g} 0 0 0" '
        f'ctrllimited="true" ctrlrange="0 1"/>'
        for i in range(len(positions))
    )
    dyn = scn.dynamics
    if dyn is None:
        obstacles = "\n".join(
            f'    <geom name="{OBSTACLE_PREFIX}{i}" type="{ob.shape}" pos="{_fmt(ob.center)}" '
            f'size="{_fmt(ob.size)}" quat="{_fmt(ob.quat)}" rgba="{_fmt(ob.rgba)}" '
            f'material="rock" contype="2" conaffinity="1"/>'
            for i, ob in enumerate(scn.obstacles)
        )
        com, assets = (0.0, 0.0, 0.0), ""
    else:
        obstacles = "\n".join(
            f'    <body name="{DEBRIS_PREFIX}{i}" mocap="true" pos="{_fmt(ob.center)}" quat="{_fmt(ob.quat)}">\n'
            f'      <geom name="{OBSTACLE_PREFIX}{i}" type="{ob.shape}" size="{_fmt(ob.size)}" '
            f'rgba="{_fmt(ob.rgba)}" material="debris" contype="2" conaffinity="1"/>\n'
            f"    </body>"
            for i, ob in enumerate(scn.obstacles)
        )
        com, assets = dyn.body.com_offset, DEBRIS_ASSETS
        lamp = _fmt([dyn.sensing.onboard_light] * 3)
        sites += (
            f'\n      <light name="{ONBOARD_LIGHT}" pos="{h + 0.002:.9g} 0 0" dir="1 0 0" directional="false" '
            f'castshadow="false" cutoff="55" exponent="2" diffuse="{lamp}" specular="0.1 0.1 0.1"/>'
        )
    return f"""<mujoco model="orbit_cubesat">
  <option timestep="{cfg.dt / cfg.substeps:.9g}" gravity="0 0 0" density="0" viscosity="0"/>
  <statistic extent="1" center="0 0 0"/>
  <visual>
    <global offwidth="{size}" offheight="{size}" fovy="{cam.fovy_deg:.9g}"/>
    <quality shadowsize="0" offsamples="0"/>
    <map znear="{cam.near:.9g}" zfar="{cam.far:.9g}"/>
    <headlight active="0" ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>
  </visual>
  <asset>
    <material name="rock" specular="0.1" shininess="0.1" reflectance="0"/>
    <material name="panel" rgba="0.15 0.2 0.45 1" specular="0.6" shininess="0.6"/>{assets}
  </asset>
  <worldbody>
    <light name="sun" directional="true" castshadow="false" pos="0 0 0"
           dir="{_fmt(light.sun_direction)}" diffuse="{diffuse}" specular="0.3 0.3 0.3" ambient="{ambient}"/>
    <body name="{BODY}" pos="0 0 0" quat="{_fmt(scn.initial_quat)}">
      <freejoint name="root"/>
      <inertial pos="{_fmt(com)}" mass="{sat.dry_mass + sat.fuel_mass:.9g}" diaginertia="1e-3 1e-3 1e-3"/>
      <geom name="{HULL}" type="box" size="{h:.9g} {h:.9g} {h:.9g}" material="panel"
            contype="1" conaffinity="2" mass="0"/>
      <camera name="{CAMERA}" pos="{h + 0.001:.9g} 0 0" xyaxes="0 -1 0 0 0 1" fovy="{cam.fovy_deg:.9g}"/>
{sites}
    </body>
{obstacles}
  </worldbody>
  <actuator>
{motors}
  </actuator>
</mujoco>
"""

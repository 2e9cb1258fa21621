"""A headless PyBullet world: supports as boxes, objects from their URDFs, settling, contact queries.

Poses are ``[x, y, z, qx, qy, qz, qw]`` of an object's mesh frame (its centre of mass, see the objects
stage) in the world frame, metres; z is up and gravity is -9.81 m/s^2 along z.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

from tohgs.assets.manifest import check_object_urdf
from tohgs.assets.supports import Support
from tohgs.sim.client import DirectClient


@dataclass(frozen=True)
class PhysicsSettings:
    """Simulation settings (SI units).

    Attributes:
        time_step: s per step (PyBullet's default 1/240).
        solver_iterations: constraint solver iterations per step.
        settle_time: longest settling simulation, s (the paper's 5 s).
        rest_speed: bodies whose linear (m/s) and angular (rad/s) speeds stay below this for
            ``rest_window`` s are at rest; settling stops early then.
        rest_window: s.
        friction: lateral friction of every body.
        verify_time: after settling, bodies are simulated this much longer, s, and must move less than
            ``verify_distance`` (m) and ``verify_angle`` (rad): a body momentarily still on an edge fails.
    """

    time_step: float = 1.0 / 240.0
    solver_iterations: int = 50
    settle_time: float = 5.0
    rest_speed: float = 0.005
    rest_window: float = 0.25
    friction: float = 0.8
    verify_time: float = 0.5
    verify_distance: float = 0.001
    verify_angle: float = 0.01


def pose_of(position, orientation) -> np.ndarray:
    return np.asarray(list(position) + list(orientation), dtype=np.float64)


class World(DirectClient):
    """One PyBullet client (DIRECT mode) with helpers; use as a context manager."""

    def __init__(self, settings: PhysicsSettings = PhysicsSettings(), gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)):
        super().__init__()
        self.settings = settings
        self.gravity = gravity
        self.reset()

    def reset(self) -> None:
        """Empty the world."""
        self.reset_simulation(self.gravity, self.settings.time_step, self.settings.solver_iterations,
                              deterministicOverlappingPairs=1)

    def add_support(self, support: Support, pose: np.ndarray | None = None) -> list[int]:
        """Static box bodies of a support placed at ``pose`` (default: the world origin)."""
        pos, orn = (np.zeros(3), np.array([0, 0, 0, 1.0])) if pose is None else (pose[:3], pose[3:])
        ids = []
        for box in support.boxes:
            col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=box.half_extents, physicsClientId=self.cid)
            vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=box.half_extents, rgbaColor=[0.62, 0.5, 0.38, 1],
                                       physicsClientId=self.cid)
            p, o = pb.multiplyTransforms(pos, orn, box.center, [0, 0, 0, 1])
            body = pb.createMultiBody(0, col, vis, basePosition=p, baseOrientation=o, physicsClientId=self.cid)
            pb.changeDynamics(body, -1, lateralFriction=self.settings.friction, physicsClientId=self.cid)
            ids.append(body)
        return ids

    def add_object(self, urdf: str | Path, pose: np.ndarray, static: bool = False,
                   color: tuple[float, float, float, float] | None = None) -> int:
        """Load an object's URDF (collision = its convex decomposition) at ``pose``; ``static`` makes it fixed.
        The URDF and its folder's files are checked against their checksums first
        (:func:`tohgs.assets.manifest.check_object_urdf`: ``ValueError`` naming a damaged file)."""
        check_object_urdf(urdf)
        body = pb.loadURDF(str(urdf), basePosition=pose[:3], baseOrientation=pose[3:], useFixedBase=static,
                           flags=pb.URDF_USE_INERTIA_FROM_FILE, physicsClientId=self.cid)
        pb.changeDynamics(body, -1, lateralFriction=self.settings.friction, rollingFriction=0.0005,
                          spinningFriction=0.0005, physicsClientId=self.cid)
        if color is not None:
            pb.changeVisualShape(body, -1, rgbaColor=color, physicsClientId=self.cid)
        return body

    def _inertial(self, body: int) -> tuple[tuple, tuple]:
        """The body's inertial frame in its link frame. PyBullet turns a URDF's non-diagonal inertia into
        principal axes, and its base pose getter and setter speak of that frame, not the link's."""
        info = pb.getDynamicsInfo(body, -1, physicsClientId=self.cid)
        return info[3], info[4]

    def pose(self, body: int) -> np.ndarray:
        """The pose of the body's link frame (an object's mesh frame), whatever its inertial frame."""
        p, o = pb.getBasePositionAndOrientation(body, physicsClientId=self.cid)
        lp, lo = self._inertial(body)
        ip, io = pb.invertTransform(lp, lo)
        wp, wo = pb.multiplyTransforms(p, o, ip, io)
        return pose_of(wp, wo)

    def set_pose(self, body: int, pose: np.ndarray) -> None:
        """Place the body's link frame at ``pose`` and stop it."""
        lp, lo = self._inertial(body)
        wp, wo = pb.multiplyTransforms(pose[:3], pose[3:], lp, lo)
        pb.resetBasePositionAndOrientation(body, wp, wo, physicsClientId=self.cid)
        pb.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.cid)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            pb.stepSimulation(physicsClientId=self.cid)

    def settle(self, bodies: list[int], max_time: float | None = None) -> float:
        """Simulate until every body in ``bodies`` is at rest, at most ``max_time`` s; returns the time simulated."""
        s = self.settings
        max_steps = int(round((s.settle_time if max_time is None else max_time) / s.time_step))
        window = max(1, int(round(s.rest_window / s.time_step)))
        still = 0
        for i in range(max_steps):
            pb.stepSimulation(physicsClientId=self.cid)
            moving = False
            for b in bodies:
                lin, ang = pb.getBaseVelocity(b, physicsClientId=self.cid)
                if max(map(abs, lin)) > s.rest_speed or max(map(abs, ang)) > s.rest_speed:
                    moving = True
                    break
            still = 0 if moving else still + 1
            if still >= window:
                return (i + 1) * s.time_step
        return max_steps * s.time_step

    def settle_and_verify(self, bodies: list[int], max_time: float | None = None) -> bool:
        """:meth:`settle`, then simulate ``verify_time`` more; whether no body moved beyond the tolerances."""
        self.settle(bodies, max_time)
        before = [self.pose(b) for b in bodies]
        self.step(int(round(self.settings.verify_time / self.settings.time_step)))
        for b, p in zip(bodies, before):
            q = self.pose(b)
            if np.linalg.norm(q[:3] - p[:3]) > self.settings.verify_distance or \
                    quat_angle(q[3:], p[3:]) > self.settings.verify_angle:
                return False
        return True

    def touching(self, a: int, b: int, margin: float) -> bool:
        """Whether the collision shapes of bodies ``a`` and ``b`` are closer than ``margin`` metres."""
        return len(pb.getClosestPoints(a, b, distance=margin, physicsClientId=self.cid)) > 0

    def render(self, eye: np.ndarray, target: np.ndarray, width: int = 320, height: int = 240, fov: float = 40.0
               ) -> np.ndarray:
        """A (H, W, 3) uint8 image from PyBullet's CPU renderer (TinyRenderer, headless)."""
        view = pb.computeViewMatrix(eye.tolist(), target.tolist(), [0, 0, 1], physicsClientId=self.cid)
        proj = pb.computeProjectionMatrixFOV(fov, width / height, 0.01, 10.0, physicsClientId=self.cid)
        img = pb.getCameraImage(width, height, view, proj, renderer=pb.ER_TINY_RENDERER,
                                lightDirection=[0.4, -0.6, 1.0], shadow=1, physicsClientId=self.cid)[2]
        return np.reshape(np.asarray(img, dtype=np.uint8), (height, width, 4))[..., :3]


def random_quaternion(rng: np.random.Generator) -> np.ndarray:
    """A uniformly distributed unit quaternion (x, y, z, w)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def yaw_quaternion(yaw: float) -> np.ndarray:
    return np.array([0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions: the rotation b then a."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def quat_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two orientations, radians."""
    d = abs(float(np.dot(a, b)))
    return 2.0 * np.arccos(min(1.0, d))

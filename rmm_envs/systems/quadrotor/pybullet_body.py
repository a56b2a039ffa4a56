"""The quadrotor's body in PyBullet: its URDF file, and holding a wrench on it for some steps."""

from __future__ import annotations

from importlib import resources

__all__ = ["push_body", "urdf_path"]


def urdf_path() -> str:
    """The body's URDF file, installed with the package."""
    return str(resources.files("rmm_envs") / "assets" / "quadrotor.urdf")


def push_body(p, client: int, body: int, control, n_steps: int, stop_on_contact: bool = False) -> tuple[int, bool]:
    """Hold ``control = (F, Mx, My, Mz)`` for ``n_steps`` PyBullet steps of ``body``: before each
    step, the thrust ``F`` along the body z axis and the moments in the body frame
    (``applyExternalForce`` / ``applyExternalTorque`` in ``LINK_FRAME``; PyBullet clears them after
    every step).  Returns ``(steps taken, whether the body touched anything after a step)``;
    with ``stop_on_contact`` it stops after the first step that ends in contact."""
    force = [0.0, 0.0, float(control[0])]
    torque = [float(control[1]), float(control[2]), float(control[3])]
    touched = False
    for k in range(n_steps):
        p.applyExternalForce(body, -1, force, [0, 0, 0], p.LINK_FRAME, physicsClientId=client)
        p.applyExternalTorque(body, -1, torque, p.LINK_FRAME, physicsClientId=client)
        p.stepSimulation(physicsClientId=client)
        if p.getContactPoints(bodyA=body, physicsClientId=client):
            touched = True
            if stop_on_contact:
                return k + 1, True
    return n_steps, touched

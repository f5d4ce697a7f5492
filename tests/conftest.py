"""Shared fixtures: the shipped machine and random joint sets / poses where it can work."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

import verne_post as vp
from verne_post.api import Status, classify, pose_margins
from verne_post.kinematics import kernels


@pytest.fixture(scope="session")
def machine() -> vp.Machine:
    return vp.load_machine()


@pytest.fixture(scope="session")
def geom(machine: vp.Machine) -> vp.Geometry:
    return machine.kinematic_geometry()


def random_usable_joints(machine: vp.Machine, n: int, seed: int, tool_length: float = 0.0) -> np.ndarray:
    """At least ``n`` random joint sets (mm, rad) that are in limits and clear of singularities.

    Sampled uniformly in the joint box, kept where the forward kinematics has a working
    assembly and the machine's status is ok (independent of the IK under test).
    """
    rng = np.random.default_rng(seed)
    lower = np.array([0.0, 0.0, 0.0, -np.pi / 2, -np.pi])
    upper = np.array([1300.0, 1300.0, 1300.0, np.pi / 2, np.pi])
    kept = []
    total = 0
    while total < n:
        joints = lower + (upper - lower) * rng.random((2 * n, 5))
        fk = vp.forward_kinematics(machine, joints, tool_length=tool_length)
        found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, tool_length)
        ok = classify(machine, joints, fk.reachable, found) == Status.OK
        kept.append(joints[ok])
        total += int(ok.sum())
    return np.concatenate(kept)[:n]


@pytest.fixture(params=["numba", "numpy"])
def kinematics_route(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """Each route of the working-mode kinematics in turn (verne_post.kinematics.kernels)."""
    if request.param == "numba":
        pytest.importorskip("numba")  # the test extra installs it
    monkeypatch.setenv(kernels.ROUTE_VARIABLE, request.param)
    kernels._numba_kernels.cache_clear()
    assert kernels.route().split()[0] == request.param
    yield request.param
    kernels._numba_kernels.cache_clear()


@pytest.fixture(autouse=True)
def _no_kinematics_route_left_behind() -> Iterator[None]:
    """A test that switches the kinematics route (VERNE_POST_KERNELS through monkeypatch) leaves no
    cached route behind: after monkeypatch has restored the environment (autouse fixtures are torn
    down last), the next test reads the route afresh."""
    yield
    kernels._numba_kernels.cache_clear()

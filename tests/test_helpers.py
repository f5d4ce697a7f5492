"""Posting with helper processes (planning and verification beside the main process) must give
what posting in one process gives: the same bytes, findings, violations and figures, and the
same refusals; a failure inside a helper reaches the caller. The independent route is the
one-process pipeline (``workers=1``), itself checked against posting whole in tests/test_parts.py.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import PPoly

import verne_post as vp
import verne_post.pipeline as pipeline
from verne_post.errors import HelperError
from verne_post.options import PostOptions
from verne_post.pipeline import post
from verne_post.planning import stage
from verne_post.planning.feed_planner import Cubics
from verne_post.planning.schedule import SequenceError
from verne_post.planning.timing import Limits, plan_rapid
from verne_post.processes.helpers import Pool
from verne_post.verify.verifier import Verifier

EXAMPLES = Path(__file__).parent.parent / "examples"


def _figures(posted: pipeline.Posted, machine: vp.Machine, options: PostOptions) -> dict:
    report = posted.report(machine, options)
    report.pop("seconds")
    return report


@pytest.mark.parametrize(("name", "size", "options"), [
    ("impeller_5axis.cls", 3000, PostOptions()),  # rapids, passes without rapids, the pole crossed
    ("nx_variable_axis_inch.cls", 30, PostOptions(plan=False)),  # its verification fails: the same findings
    ("nx_variable_axis_inch.cls", 30, PostOptions(optimize=True)),  # the helper plans in processes of its own
])
def test_helpers_post_what_one_process_posts(tmp_path: Path, name: str, size: int, options: PostOptions) -> None:
    machine = vp.load_machine()
    one = post(EXAMPLES / name, machine, replace(options, workers=1), tmp_path / "one.nc", part_poses=size,
               timing_figures=True)
    helped = post(EXAMPLES / name, machine, replace(options, workers=2), tmp_path / "helped.nc", part_poses=size,
                  timing_figures=True)
    assert helped.parts == one.parts > 3
    assert helped.verification == replace(one.verification, source=helped.verification.source)
    assert _figures(helped, machine, options) == _figures(one, machine, options)
    assert "waiting" in helped.seconds and "waiting" not in one.seconds
    if one.verification.ok:
        assert (tmp_path / "helped.nc").read_bytes() == (tmp_path / "one.nc").read_bytes()
    else:
        assert not (tmp_path / "helped.nc").exists() and not (tmp_path / "one.nc").exists()


def test_a_part_the_helper_cannot_plan_is_a_violation_as_in_one_process(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The third part's planning fails (in whichever process plans it): the same violation at the
    same CL line, the later parts not planned, nothing written."""
    real = stage.plan_program
    sizes: list[int] = []

    def recording(joints: np.ndarray, *args: object, **kwargs: object) -> object:
        sizes.append(len(joints))
        return real(joints, *args, **kwargs)

    machine = vp.load_machine()
    monkeypatch.setattr(stage, "plan_program", recording)
    post(EXAMPLES / "impeller_5axis.cls", machine, PostOptions(workers=1, plan=True), None, part_poses=3000)
    third = sizes[2]
    assert sizes.count(third) == 1

    def failing(joints: np.ndarray, *args: object, **kwargs: object) -> object:
        if len(joints) == third:  # the same part in any process (a counter would be per process)
            raise SequenceError("test: no plan", 5)
        return real(joints, *args, **kwargs)

    monkeypatch.setattr(stage, "plan_program", failing)  # before the helpers fork: they have it too
    outcomes = []
    for workers in (1, 2):
        target = tmp_path / f"w{workers}.nc"
        posted = post(EXAMPLES / "impeller_5axis.cls", machine, PostOptions(workers=workers), target,
                      part_poses=3000)
        assert not target.exists()
        outcomes.append((posted.violations, _figures(posted, machine, PostOptions())))
    assert outcomes[0] == outcomes[1]
    violations = outcomes[0][0]
    assert [v.kind for v in violations] == ["timing"] and "test: no plan" in violations[0].message
    assert outcomes[0][1]["timing"] is None  # the parts after it were not planned


def test_an_error_in_a_helper_reaches_the_caller(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(*args: object, **kwargs: object) -> object:
        raise RuntimeError("broken verifier")

    monkeypatch.setattr(Verifier, "read", broken)
    with pytest.raises(RuntimeError, match="broken verifier"):
        post(EXAMPLES / "nx_swarf_inch_crlf.cls", vp.load_machine(), PostOptions(workers=2), tmp_path / "x.nc",
             part_poses=50)
    assert not (tmp_path / "x.nc").exists()


@pytest.mark.parametrize("which", ["planning", "verification"])
def test_a_helper_that_dies_is_one_error_and_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            which: str) -> None:
    """A helper killed mid-run (the OOM killer, say): a one-line HelperError (exit 1), no file."""
    parent = os.getpid()
    real_plan, real_read = stage.plan_program, Verifier.read

    def die_in_child(real: Callable[..., object]) -> Callable[..., object]:
        def dying(*args: object, **kwargs: object) -> object:
            if os.getpid() != parent:
                os._exit(9)
            return real(*args, **kwargs)
        return dying

    if which == "planning":
        monkeypatch.setattr(stage, "plan_program", die_in_child(real_plan))
    else:
        monkeypatch.setattr(Verifier, "read", die_in_child(real_read))
    target = tmp_path / "x.nc"
    with pytest.raises(HelperError, match="helper process stopped") as caught:
        post(EXAMPLES / "nx_swarf_inch_crlf.cls", vp.load_machine(), PostOptions(workers=2), target, part_poses=50)
    assert caught.value.exit_code == 1 and "\n" not in str(caught.value)
    assert not target.exists() and not list(tmp_path.iterdir())


def test_cubics_evaluate_as_scipy_ppoly() -> None:
    """Values and first three derivatives, inside, on the breaks and beyond both ends, for scalar
    and vector values, against scipy's PPoly (extrapolate=True)."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        pieces = int(rng.integers(1, 9))
        breaks = np.cumsum(rng.uniform(0.01, 2.0, pieces + 1)) - 1.0
        shape = (4, pieces) if rng.random() < 0.5 else (4, pieces, 5)
        coef = rng.normal(size=shape)
        x = np.concatenate([rng.uniform(breaks[0] - 1, breaks[-1] + 1, 50), breaks])
        ours, theirs = Cubics(breaks, coef), PPoly(coef, breaks, extrapolate=True)
        for nu in range(4):
            np.testing.assert_allclose(ours(x, nu), theirs(x, nu), rtol=1e-12, atol=1e-12)


def test_a_rapid_plan_crosses_processes() -> None:
    """ruckig's trajectory cannot be pickled: the plan is planned again on arrival, to the same move."""
    limits = Limits.from_machine(vp.load_machine())
    rng = np.random.default_rng(3)
    for _ in range(50):
        start, end = rng.uniform(-50, 50, 5), rng.uniform(-50, 50, 5)
        plan = plan_rapid(start, end, limits)
        copy = pickle.loads(pickle.dumps(plan))
        assert copy.duration == plan.duration
        t = np.linspace(0, plan.duration, 17)
        for ours, theirs in zip(copy.sample(t), plan.sample(t), strict=True):
            np.testing.assert_array_equal(ours, theirs)
    still = pickle.loads(pickle.dumps(plan_rapid(start, start, limits)))
    assert still.duration == 0.0 and still.trajectory is None


def _power_and_pid(context: np.ndarray, k: int) -> tuple[np.ndarray, int]:
    if k < 0:
        raise ValueError(f"test: call {k} fails")
    return np.linalg.matrix_power(context, k), os.getpid()


def test_a_pool_gives_what_one_process_gives_in_order_and_raises_what_a_call_raised() -> None:
    """Pool (placement's room runs its full checks in one): each call's result, bit for bit and in
    the order of the calls, whichever process ran it; the context is the forked processes' own
    (inherited, not passed); a call that raises raises in the caller."""
    rng = np.random.default_rng(7)
    context = rng.normal(size=(6, 6)) / 3.0
    calls = [(k,) for k in range(1, 9)]
    alone = forked = None
    try:
        alone = Pool(context, 1)
        forked = Pool(context, 2)
        here = alone.map(_power_and_pid, calls)
        there = forked.map(_power_and_pid, calls)
        assert {pid for _, pid in here} == {os.getpid()}
        assert os.getpid() not in {pid for _, pid in there}
        for (a, _), (b, _), (k,) in zip(here, there, calls, strict=True):
            assert np.array_equal(a, b)
            assert np.allclose(a, np.linalg.matrix_power(context, k))
        with pytest.raises(ValueError, match="call -1 fails"):
            forked.map(_power_and_pid, [(2,), (-1,)])
    finally:
        for pool in (alone, forked):
            if pool is not None:
                pool.close()

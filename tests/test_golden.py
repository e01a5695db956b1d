"""Results users get through the public paths stay what they were when the goldens were
recorded (``tests/golden/record.py``): seeded ``quadfault simulate`` flights with and without
sensor noise and with effects, ``quadfault estimate`` series (IRLS, improved IRLS, EKF),
zero-action rollouts of each env id and of the vector env, and the agents' closed-loop
flights. Agreement to 1e-9 (relative to each array's scale) means a refactoring changed
nothing a user can see."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent / "golden"
GOLDEN = HERE / "golden.npz"
_spec = importlib.util.spec_from_file_location("golden_record", HERE / "record.py")
record = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(record)


#: seeded flights, estimates and rollouts of 10-80 s each: the full suite runs them (CI);
#: run this file before landing a change that must not move a number
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def golden():
    return dict(np.load(GOLDEN))


def _compare(golden, fresh, prefix):
    want = {k: v for k, v in golden.items() if k.startswith(prefix)}
    assert want, f"no golden arrays under {prefix}"
    missing = sorted(set(want) - set(fresh))
    assert not missing, f"outputs no longer produced: {missing}"
    bad = []
    for key, ref in want.items():
        got = np.asarray(fresh[key], dtype=float)
        if got.shape != ref.shape:
            bad.append(f"{key}: shape {got.shape} != {ref.shape}")
            continue
        scale = max(1.0, float(np.nanmax(np.abs(ref))) if ref.size else 1.0)
        same_nan = np.array_equal(np.isnan(got), np.isnan(ref))
        err = float(np.nanmax(np.abs(got - ref))) if ref.size else 0.0
        if not same_nan or err > 1e-9 * scale:
            bad.append(f"{key}: max abs difference {err:.3g} (scale {scale:.3g})")
    assert not bad, "\n".join(bad)


def test_simulate_and_estimate_match_the_goldens(golden, tmp_path):
    fresh = record.flights(tmp_path)
    _compare(golden, fresh, "sim/")
    _compare(golden, fresh, "est/")


def test_env_rollouts_match_the_goldens(golden):
    fresh = record.rollouts()
    _compare(golden, fresh, "env/")
    _compare(golden, fresh, "vec/")


def test_agent_flights_match_the_goldens(golden):
    _compare(golden, record.agent_flights(), "agent/")

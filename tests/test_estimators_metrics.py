"""The paper's metrics on hand-made series with known answers."""

import numpy as np
import pytest

from estimators.base import EstimateSeries
from estimators.metrics import fault_windows, mean_or_none, score, window_masks
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.model.vehicle import Vehicle

DT = 1e-3


def _recording(eta_true, windows=None):
    n = len(eta_true)
    t = DT * np.arange(n)
    quat = np.tile([1.0, 0, 0, 0], (n, 1))
    meta = {} if windows is None else {"fault_windows": windows}
    return Recording(
        t=t,
        omega=np.zeros((n, 3)),
        thrust_cmd=np.full((n, 4), 2.45),
        vehicle=Vehicle(),
        position=np.zeros((n, 3)),
        velocity=np.zeros((n, 3)),
        quaternion=quat,
        eta_true=np.asarray(eta_true, float),
        meta=meta,
    )


def _series(rec, eta_hat, name="test", config=None, warmup=0):
    status = np.array(["warmup"] * warmup + ["ok"] * (len(rec) - warmup))
    return EstimateSeries(
        t=rec.t.copy(),
        eta=np.asarray(eta_hat, float),
        sd=None,
        status=status,
        estimator=name,
        config=config or {},
        seconds=1.5,
    )


def test_rmse_and_std_on_known_errors():
    n = 1000
    truth = np.ones((n, 4))
    rec = _recording(truth)
    err = np.zeros((n, 4))
    err[:, 0] = 0.1  # constant bias: rmse 0.1, std 0
    err[:, 1] = np.where(np.arange(n) % 2 == 0, 0.2, -0.2)  # zero-mean +-0.2
    hat = truth - err
    s = score(rec, _series(rec, hat))
    assert s.rmse[0] == pytest.approx(0.1) and s.std[0] == pytest.approx(0.0, abs=1e-12)
    assert s.rmse[1] == pytest.approx(0.2)
    assert s.std[1] == pytest.approx(0.2 * np.sqrt(n / (n - 1)))  # N-1 normalisation
    assert s.rmse[2] == 0.0 and s.spike is None and s.excess_spike is None
    assert s.seconds == 1.5 and s.n == n
    d = s.to_contract()
    assert set(d) >= {"rmse", "std", "spike", "seconds"} and d["spike"] is None


def test_warmup_rows_are_not_scored():
    n = 100
    truth = np.ones((n, 4))
    rec = _recording(truth)
    hat = truth.copy()
    hat[:10] = 0.0  # huge error only during warm-up
    s = score(rec, _series(rec, hat, warmup=10))
    assert s.rmse == (0.0, 0.0, 0.0, 0.0) and s.n == n - 10


def test_spike_is_the_max_error_in_the_other_motors_windows():
    n = 3000
    t = DT * np.arange(n)
    truth = np.ones((n, 4))
    truth[(t >= 1.0) & (t <= 1.5), 1] = 0.5  # motor 2 fault
    truth[(t >= 2.0) & (t <= 2.5), 2] = 0.5  # motor 3 fault
    rec = _recording(truth, [[2, 1.0, 1.5], [3, 2.0, 2.5]])
    err = np.zeros((n, 4))
    err[int(round(1.2 / DT)), 0] = 0.2  # inside motor 2's window
    err[int(round(1.528 / DT)), 0] = -0.3  # inside the 0.03 s pad after it (signed)
    err[int(round(1.6 / DT)), 0] = 0.9  # outside every window: not a spike
    err[int(round(2.3 / DT)), 1] = 0.25  # motor 2's error during motor 3's fault
    err[int(round(1.2 / DT)), 1] = 0.7  # motor 2's error in its OWN window: not counted
    s = score(rec, _series(rec, truth - err))
    assert s.spike[0] == pytest.approx(0.3)
    assert s.spike[1] == pytest.approx(0.25)
    assert s.spike[2] == pytest.approx(0.0)
    assert s.spike[3] == pytest.approx(0.0)
    # excess over the 99.9th percentile of |e| outside all windows (the 0.9 outlier is one
    # sample in ~1800, above the percentile's reach but it lifts it a little)
    quiet = np.ones(n, bool)
    quiet[(t >= 1.0 - 0.031) & (t <= 1.5 + 0.031)] = False
    quiet[(t >= 2.0 - 0.031) & (t <= 2.5 + 0.031)] = False
    base = np.percentile(np.abs(err[quiet, 0]), 99.9)
    assert s.excess_spike[0] == pytest.approx(0.3 - base)
    assert mean_or_none(s.spike) == pytest.approx((0.3 + 0.25) / 4)


def test_window_is_extended_to_the_band_and_padded():
    """As in the reference, the levels are the samples just before and after the listed
    window; the window grows until the truth is within 3 % of them, then +-30 samples."""
    n = 2000
    t = DT * np.arange(n)
    truth = np.ones((n, 4))
    truth[1000:1500, 0] = 0.5
    truth[1500:1503, 0] = [0.6, 0.8, 0.95]  # a slow recovery after the listed end
    masks = window_masks(t, truth, [(1, 1.0, 1.499)])
    on = np.flatnonzero(masks[0])
    assert on[0] == 999 - 30  # the sample before the fault is at the old level
    # after-level = truth[1500] = 0.6: 1500 is already inside its band
    assert on[-1] == 1500 + 30
    assert np.all(np.diff(on) == 1) and not masks[1:].any()
    # a wider band of the after-level reaches no further; a step recovery adds one sample
    truth[1500:1503, 0] = 1.0
    on = np.flatnonzero(window_masks(t, truth, [(1, 1.0, 1.499)])[0])
    assert on[-1] == 1500 + 30


def test_spike_none_for_a_motor_with_no_other_window():
    n = 1000
    truth = np.ones((n, 4))
    truth[400:600, 0] = 0.5
    rec = _recording(truth, [[1, 0.4, 0.6]])
    s = score(rec, _series(rec, truth))
    assert s.spike[0] is None and s.spike[1] == 0.0


def test_reference_alignment_uses_the_window_start():
    n = 500
    truth = np.tile(np.linspace(1.0, 0.5, n)[:, None], (1, 4))
    rec = _recording(truth)
    # an estimator that reports the truth of 9 rows earlier (the window start, n = 10)
    hat = np.vstack((np.repeat(truth[:1], 9, axis=0), truth[:-9]))
    est = _series(rec, hat, name="irls", config={"window": 10}, warmup=9)
    assert max(score(rec, est, align="reference").rmse) == pytest.approx(0.0, abs=1e-15)
    assert min(score(rec, est, align="end").rmse) > 0.004


def test_bad_input_is_a_clear_error():
    rec = _recording(np.ones((100, 4)), [[7, 0.1, 0.2]])
    with pytest.raises(ConfigError, match="fault_windows"):
        fault_windows(rec)
    with pytest.raises(ConfigError, match="align"):
        score(
            _recording(np.ones((100, 4))),
            _series(_recording(np.ones((100, 4))), np.ones((100, 4))),
            align="start",
        )


def test_coverage_counts_errors_within_one_sigma():
    n = 1000
    truth = np.ones((n, 4))
    rec = _recording(truth)
    err = np.tile(np.where(np.arange(n) % 4 == 0, 0.2, 0.05)[:, None], (1, 4))
    err[:, 3] *= -1  # the sign does not matter
    s = _series(rec, truth - err)
    assert score(rec, s).coverage is None  # no sd
    sd = np.full((n, 4), 0.1)
    sd[:10, 2] = np.nan  # rows without sd are not counted
    s = EstimateSeries(
        t=rec.t.copy(),
        eta=truth - err,
        sd=sd,
        status=np.array(["ok"] * n),
        estimator="test",
        config={},
        seconds=0.0,
    )
    cov = score(rec, s).coverage
    assert cov[0] == pytest.approx(0.75) and cov[3] == pytest.approx(0.75)
    assert cov[2] == pytest.approx(np.mean(np.arange(10, n) % 4 != 0))
    assert score(rec, s).to_contract()["coverage"] == list(cov)

"""The online ``SlidingWindowIRLS.update``: the compiled one-call update against a readable
Python loop of the same rules over the numpy oracle (through every guard), against ``run()``,
and its diagnostics and bad-input handling."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from oracles import irls_numpy as oracle

from estimators.base import Sample, samples
from estimators.irls import IRLSConfig, IRLSDiagnostics, SlidingWindowIRLS
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.sim.simulator import simulate


@pytest.fixture(scope="module")
def fault_flight():
    """A motor fault at 0.2 s (the change completion triggers on it)."""
    sc = Scenario(
        "fault",
        0.4,
        EfficiencySchedule(
            ConstantEfficiency((1.0, 0.9, 0.8, 0.95)), (AbruptFault(motor=3, onset=0.2, level=0.4),)
        ),
        Circle(),
    )
    return simulate(sc, seed=5).without_truth()


def _troubled_rows(rec):
    """The flight's samples with every guard in them: a NaN, a repeated time, a stretch of
    zero thrust, a malformed command, a silent rotor (ill-conditioned)."""
    rows = list(samples(rec))
    rows[60] = rows[60]._replace(p=np.array([np.nan, 0.0, 0.0]))
    rows[120] = rows[120]._replace(t=rows[119].t)
    for k in range(150, 165):
        rows[k] = rows[k]._replace(f=np.zeros(4))
    rows[180] = rows[180]._replace(f=np.zeros(3))
    for k in range(300, 312):
        rows[k] = rows[k]._replace(f=np.array([2.5, 0.0, 2.5, 2.5]))
    return rows


@pytest.mark.slow
@pytest.mark.parametrize(
    "cfg", [IRLSConfig(), IRLSConfig.improved(prefilter=0.0), IRLSConfig.improved()]
)
def test_online_update_follows_the_plain_rules_through_every_guard(fault_flight, cfg):
    est = SlidingWindowIRLS(fault_flight.vehicle, cfg)
    ref = oracle.OnlineIRLS(fault_flight.vehicle, cfg)
    seen = set()
    for s in _troubled_rows(fault_flight):
        out = est.update(s)
        status, eta = ref.update(s)
        seen.add(out.status)
        assert out.status == status, s.t
        np.testing.assert_allclose(out.eta, eta, rtol=0, atol=1e-9)
    assert {"ok", "warmup", "bad_sample", "no_excitation"} <= seen
    # with the prefilter the silent rotor's earlier segments stay in the filtered regressors
    # (decaying over ``prefilter``), so its 12 samples leave the window conditioned
    assert ("ill_conditioned" in seen) == (cfg.prefilter == 0.0)
    if cfg.change_completion:
        assert est.change_events == ref.completion.events >= 1


@pytest.mark.slow
@pytest.mark.parametrize("improved", [False, True])
def test_compiled_online_update_equals_run(fault_flight, improved):
    cfg = IRLSConfig.improved() if improved else IRLSConfig()
    est = SlidingWindowIRLS(fault_flight.vehicle, cfg)
    online = [est.update(s) for s in samples(fault_flight)]
    offline = SlidingWindowIRLS(fault_flight.vehicle, cfg).run(fault_flight)
    np.testing.assert_allclose(np.array([e.eta for e in online]), offline.eta, rtol=0, atol=1e-12)
    assert [e.status for e in online] == list(offline.status)
    sd = np.array([np.full(4, np.nan) if e.sd is None else e.sd for e in online])
    np.testing.assert_allclose(sd, offline.sd, rtol=0, atol=1e-12)


def test_online_estimates_do_not_alias_the_estimator_state(fault_flight):
    est = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig())
    outs = [est.update(s) for s in samples(fault_flight.slice(0, 40))]
    first = outs[20].eta.copy(), outs[20].sd.copy(), outs[20].diagnostics.weights.copy()
    for s in samples(fault_flight.slice(40, 80)):
        est.update(s)
    np.testing.assert_array_equal(outs[20].eta, first[0])
    np.testing.assert_array_equal(outs[20].sd, first[1])
    np.testing.assert_array_equal(outs[20].diagnostics.weights, first[2])
    assert est.eta is not est.eta  # a copy


def test_lazy_diagnostics_are_irls_diagnostics(fault_flight):
    est = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig())
    for s in samples(fault_flight.slice(0, 30)):
        out = est.update(s)
    d = out.diagnostics
    assert isinstance(d, IRLSDiagnostics) and dataclasses.is_dataclass(d)
    fields = dataclasses.asdict(d)
    assert set(fields) == {f.name for f in dataclasses.fields(IRLSDiagnostics)}
    assert fields["status"] == out.status == "ok"
    assert len(fields["inner_iterations"]) >= 1 and all(k > 0 for k in d.inner_iterations)
    assert d.weights.shape == (9,) and d.rejected == tuple(np.flatnonzero(d.weights == 0))
    assert np.isfinite(d.cond) and d.dual_history is None
    assert "inner_iterations=" in repr(d)


def test_malformed_samples_restart_the_window(fault_flight):
    est = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig())
    rows = list(samples(fault_flight.slice(0, 30)))
    for bad, why in (
        (rows[12]._replace(R=np.eye(4)), "non-finite or malformed sample"),
        (("not", "a", "sample"), "non-finite or malformed sample"),
        (rows[11], "time not increasing"),
    ):
        est.reset()
        assert [est.update(s).status for s in rows[:13]][-1] == "ok"
        out = est.update(bad)
        assert out.status == "bad_sample" and out.diagnostics.message.startswith(why)
        assert np.all(np.isfinite(out.eta))
        assert est.update(rows[13]).status == "warmup"
    est.reset()
    assert [est.update(s).status for s in rows[:10]] == ["warmup"] * 9 + ["ok"]
    bad = Sample(rows[10].t, rows[10].p, rows[10].v, rows[10].R, rows[10].w, [1, 1, np.inf, 1])
    assert est.update(bad).status == "bad_sample"


def test_record_history_online_gives_the_kkt_histories(fault_flight):
    est = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig(record_history=True))
    plain = SlidingWindowIRLS(fault_flight.vehicle, IRLSConfig())
    for s in samples(fault_flight.slice(0, 30)):
        out, ref = est.update(s), plain.update(s)
        np.testing.assert_array_equal(out.eta, ref.eta)
    d = out.diagnostics
    assert len(d.gap_history) == len(d.inner_iterations) >= 1
    assert [len(g) for g in d.dual_history] == list(d.inner_iterations)
    assert d.gap_history[-1][-1] < 1e-6 and d.residual_history[-1][-1] > 0

"""Named state: the declared layouts of the estimators' flat buffers. Offsets come from the
declarations, packing is by name, and the compiled views of every piece are the Python
views (same memory, same shape) for every estimator with a flat state (IRLS, EKF, RLS, UKF),
single and batched."""

from __future__ import annotations

import numpy as np
import pytest

from estimators import ekf, irls, rls, ukf
from estimators.state import counts, fields, pack
from quadfault.errors import ConfigError
from quadfault.model.vehicle import Vehicle


def test_fields_derive_the_start_rows_from_the_counts():
    rows = fields("Rows", "a", ("b", 3), "c", ("rest", 0))
    assert (rows.a, rows.b, rows.c, rows.rest, rows.size) == (0, 1, 4, 5, 5)
    assert counts(rows) == {"a": 1, "b": 3, "c": 1, "rest": 0}
    with pytest.raises(ValueError, match="only the last"):
        fields("Bad", ("open", 0), "a")


def test_pack_places_each_entry_by_name_and_checks_sizes():
    rows = fields("Rows", "a", ("b", 3), ("rest", 0))
    out = pack(rows, rest=[7.0, 8.0], b=np.arange(3.0), a=5.0)  # any keyword order
    np.testing.assert_array_equal(out, [5.0, 0.0, 1.0, 2.0, 7.0, 8.0])
    with pytest.raises(ConfigError, match="Rows.b: 3 values expected, got 2"):
        pack(rows, a=1.0, b=[1.0, 2.0], rest=[])
    with pytest.raises(ConfigError, match="entries"):
        pack(rows, a=1.0, b=[1.0, 2.0, 3.0])


def _same_views(compiled, python):
    assert compiled._fields == python._fields
    for name, a, b in zip(python._fields, compiled, python):
        assert a.shape == b.shape, name
        assert a.__array_interface__["data"][0] == b.__array_interface__["data"][0], name


@pytest.mark.slow
@pytest.mark.parametrize("num", [1, 3])
@pytest.mark.parametrize("n_rotors", [4, 6])
def test_compiled_pieces_are_the_declared_pieces(num, n_rotors):
    cfg = irls.IRLSConfig.improved()
    st = irls.IRLSState(cfg.window - 1, n_rotors, cfg.output_median, cfg.max_irls, num)
    ang = np.arange(n_rotors) * 2 * np.pi / n_rotors
    veh = Vehicle.from_rotors(
        0.1 * np.stack((np.cos(ang), np.sin(ang), 0 * ang), axis=1),
        [(-1) ** k for k in range(n_rotors)],
        0.006,
    )
    _const, _fp, ip = irls.irls_parameters(veh, cfg, st.offsets)
    _same_views(irls.state_pieces(st.floats, ip, num), st.views)
    est = ekf.EKFState(n_rotors, num)
    _same_views(ekf.state_pieces(est.floats, est.offsets, n_rotors, num), est.views)
    for module, batched in ((rls, rls.BatchedRLS), (ukf, ukf.BatchedUKF)):
        st = batched(veh, num)._state
        _same_views(module.state_pieces(st.floats, st.offsets, n_rotors, num), st.views)


def test_constants_are_read_by_name():
    veh = Vehicle()
    const = ekf.ekf_constants(veh, ekf.EKFConfig(q_eta=0.3))
    model = ekf.constant_arrays(const, veh.n_rotors)
    np.testing.assert_array_equal(model.A, veh.allocation)
    np.testing.assert_array_equal(model.J, veh.inertia)
    assert model.rigid[:2] == (veh.mass, veh.gravity)
    assert model.qc[-1] == pytest.approx(0.3 / ekf.NOISE_REFERENCE_DT)
    cfg = irls.IRLSConfig()
    st = irls.IRLSState(cfg.window - 1, 4, 1, cfg.max_irls)
    const, fp, ip = irls.irls_parameters(veh, cfg, st.offsets)
    J, Jinv, A, G = irls.constant_arrays(const, ip)
    np.testing.assert_array_equal(A, veh.allocation)
    np.testing.assert_array_equal(Jinv, veh.inertia_inverse)
    np.testing.assert_array_equal(G, cfg.segment_weights)
    assert const[irls.CONSTANTS.mass] == veh.mass
    assert fp[irls.FLOAT_SETTINGS.change_threshold] == cfg.change_threshold
    assert ip[irls.INT_SETTINGS.m] == cfg.window - 1
    for module, config in ((rls, rls.RLSConfig(forgetting=0.98)), (ukf, ukf.UKFConfig())):
        const = getattr(module, f"{module.__name__.split('.')[-1]}_constants")(veh, config)
        C = module.CONSTANTS
        assert const[C.mass] == veh.mass and const[C.lo] == config.eta_bounds[0]
        np.testing.assert_array_equal(const[C.Jinv : C.Jinv + 9], veh.inertia_inverse.ravel())
    const = rls.rls_constants(veh, rls.RLSConfig())
    np.testing.assert_array_equal(const[rls.CONSTANTS.A :], veh.allocation.ravel())
    A, qc, r = ukf._model(ukf.ukf_constants(veh, ukf.UKFConfig(q_eta=0.3)), veh.n_rotors)
    np.testing.assert_array_equal(A, veh.allocation)
    assert qc[ukf.X.eta] == pytest.approx(0.3 / ekf.NOISE_REFERENCE_DT)
    assert r[ukf.Y.w] == ukf.UKFConfig().r_rate

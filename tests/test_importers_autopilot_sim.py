"""The autopilot importers against the simulator: a simulated flight (known vehicle, known
thrusts) written as each autopilot logs it -- its frames, units and motor order -- and
imported back must give the simulator's thrusts, rates, specific force and allocation."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.field_logs import (
    BF_ORDER,
    PX4_ORDER,
    sim_to_blackbox,
    sim_to_dataflash,
    sim_to_px4,
)


@pytest.fixture(scope="module")
def sim():
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import simulate

    return simulate(named_scenario("nominal", duration=8.0), seed=3)


CASES = {
    "px4": ("flight.ulg", sim_to_px4, PX4_ORDER, "pyulog"),
    "ardupilot": ("flight.bin", sim_to_dataflash, PX4_ORDER, "pymavlink"),
    "blackbox": ("flight.bbl", sim_to_blackbox, BF_ORDER, None),
}


@pytest.mark.parametrize("fmt", list(CASES))
def test_import_recovers_the_simulated_flight(sim, tmp_path, fmt):
    name, writer, order, needs = CASES[fmt]
    if needs:
        pytest.importorskip(needs)
    from quadfault.io.importers import detect_format, get_importer

    path = tmp_path / name
    writer(sim, path)
    assert detect_format(path) == fmt
    veh = sim.vehicle
    A = veh.allocation[:, list(order)]
    rec = get_importer(fmt)(
        path,
        mass=veh.mass,
        inertia=np.diag(veh.inertia).tolist(),
        arm=float(abs(A[2, 0])),
        torque_coefficient=float(abs(A[3, 0])),
    )
    t = rec.t - 1.0  # the writers start the log's clock at 1 s
    # the vehicle: the simulator's allocation with its columns in the log's motor order
    np.testing.assert_allclose(rec.vehicle.allocation, A, atol=1e-6)
    # rotor thrusts: the importer's calibrated curve gives back the simulated thrusts
    f_sim = np.stack([np.interp(t, sim.t, sim.thrust_cmd[:, i]) for i in order], axis=1)
    rel = np.abs(rec.thrust_cmd - f_sim) / f_sim
    assert np.median(rel) < 0.03
    # body rates and specific force in FRD
    w_sim = np.stack([np.interp(t, sim.t, sim.omega[:, i]) for i in range(3)], axis=1)
    tol = np.radians(1.0) if fmt == "blackbox" else 1e-4  # Betaflight logs whole deg/s
    assert np.max(np.abs(rec.omega - w_sim)) < tol
    a_sim = np.interp(t, sim.t, sim.accel[:, 2])
    assert np.max(np.abs(rec.accel[:, 2] - a_sim)) < 0.02

    # the vehicle flies with these thrusts: the moment of the imported thrusts and the
    # angular acceleration of the imported rates agree as well as the simulation's own do
    def moment_fit(r):
        k = np.ones(25) / 25
        alpha = np.gradient(r.omega, r.t, axis=0)
        model = (r.thrust_cmd @ r.vehicle.allocation.T)[:, 1:3] / np.diag(veh.inertia)[:2]
        return [
            np.corrcoef(np.convolve(model[:, i], k, "same"), np.convolve(alpha[:, i], k, "same"))[
                0, 1
            ]
            for i in range(2)
        ]

    np.testing.assert_allclose(moment_fit(rec), moment_fit(sim), atol=0.15)

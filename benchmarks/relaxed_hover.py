"""The relaxed hover after a complete rotor loss: the model's solution against the
closed-form conditions, what thrust-to-weight and yaw damping it needs, and the simulator
holding it open loop.

For the paper's F450 (thrust-to-weight 2) and the complete-loss vehicle (2.75,
:func:`quadfault.model.relaxed_hover.rotor_loss_vehicle`), yaw damping D1z and the opposite
rotor's share rho, prints the solution of :func:`~quadfault.model.relaxed_hover.relaxed_hover`
(rotor 1 lost): yaw rate, spin-axis tilt, the three thrusts, the busiest rotor's share of its
limit, and the largest difference from :func:`~quadfault.model.relaxed_hover.closed_form_hover`.
Then flies the complete-loss vehicle's solution open loop (constant commands) for
``--hold`` seconds and prints how far the body rate and the centre of mass moved.

    python benchmarks/relaxed_hover.py [--hold 5]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects import parse_effect
from quadfault.model.flight import Flight
from quadfault.model.plant import Plant
from quadfault.model.relaxed_hover import (
    ROTOR_LOSS_EFFECTS,
    ROTOR_LOSS_MOMENTUM,
    SpinPhysics,
    closed_form_hover,
    hover_state,
    relaxed_hover,
    rotor_loss_vehicle,
)
from quadfault.model.vehicle import Vehicle


def table() -> None:
    print(
        "| vehicle (T/W) | D1z [N m s/rad] | rho | yaw rate [rad/s] | tilt [deg] | "
        "f1..f4 [N] | busiest rotor / limit | closed form: max diff |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for veh in (Vehicle(), rotor_loss_vehicle()):
        for gamma in (1e-3, 5e-3, 1e-2):
            for rho in (0.0, 0.3, 0.6):
                phys = SpinPhysics((1e-3, 1e-3, gamma), momentum=ROTOR_LOSS_MOMENTUM)
                h = relaxed_hover(veh, phys, 0, rho)
                cf = closed_form_hover(veh, phys, 0, rho)
                diff = max(np.max(np.abs(h.f - cf.f)), np.max(np.abs(h.w - cf.w)))
                print(
                    f"| {veh.thrust_to_weight:g} | {gamma:g} | {rho:g} | {h.yaw_rate:.2f} | "
                    f"{math.degrees(h.tilt):.1f} | {', '.join(f'{x:.2f}' for x in h.f)} | "
                    f"{h.load:.2f} | {diff:.2g} |"
                )


def hold(seconds: float) -> None:
    veh = rotor_loss_vehicle()
    phys = SpinPhysics.of(ROTOR_LOSS_EFFECTS)
    print(f"\nopen loop, {veh.name}, effects {' '.join(ROTOR_LOSS_EFFECTS)}, {seconds:g} s:")
    print(
        "| lost rotor | yaw rate [rad/s] | max |w - wbar| [rad/s] | circle radius [mm] | "
        "distance from the hover point at the end [mm] |"
    )
    print("|---|---|---|---|---|")
    n = int(round(seconds / 1e-3))
    for lost in range(4):
        h = relaxed_hover(veh, phys, lost)
        plant = Plant(veh, effects=tuple(parse_effect(s) for s in ROTOR_LOSS_EFFECTS))
        plant.reset(RigidBodyState(*hover_state(veh, h)))
        flight = Flight(plant, record_accel=False)
        flight.reset(np.random.default_rng(0))
        eta = np.ones(4)
        eta[lost] = 0.0
        flight.plan(n, lambda t, eta=eta: eta)
        rec = flight.records(n)
        flight.step(h.f, n, record=rec)
        dw = float(np.max(np.abs(rec.w[0, 1:] - h.w)))  # row 0: the measurement before reset
        end = float(np.linalg.norm(flight.state().p - np.array([0.0, 0.0, -1.0])))
        print(
            f"| {lost + 1} | {h.yaw_rate:.2f} | {dw:.2g} | {1e3 * h.circle_radius(veh):.1f} | "
            f"{1e3 * end:.1f} |"
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hold", type=float, default=5.0, help="open-loop flight [s] (5)")
    args = ap.parse_args(argv)
    table()
    hold(args.hold)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

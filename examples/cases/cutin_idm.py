#!/usr/bin/env python3
"""The cut-in case as a user-defined case (examples/cases/cut-in.toml): a
background vehicle cuts in at range R (m) and range rate R' (m/s) ahead of
the vehicle under test, here the Intelligent Driver Model of the paper's
Table III, which then follows it for 10 s. Python 3, standard library only.

It speaks tslg's external-vehicle protocol (docs/vut-protocol.md) in episode
mode: it receives each scenario by its dimensions' names and answers the
outcome (an accident: the gap closes to 0 m or below) and the criticality,
the minimum over the run of the normalised enhanced time to collision
(mnpETTC, 0 for an accident). The simulation is the built-in cut-in's
`paper-code` preset (the authors' code), operation for operation, so its
outcome on every scenario is the built-in IDM's.
"""

import json
import math
import sys

NAME = "cutin-idm"

# paper-code preset: the authors' code.
INITIAL_SPEED = 20.0  # the VUT's speed at the cut-in; the leader drives at v + R'
DT = 1.0
STEPS = 10
ACCELERATION = (-3.0, 3.0)
SPEED = (0.0, 40.0)
ACCIDENT_GAP = 0.0  # an accident is a gap <= 0 m
U_I = 100.0  # ETTC normalisation (s)

# IDM, the paper's Table III calibration.
ALPHA, V0, DELTA, S0, LENGTH, HEADWAY, B = 2.0, 18.0, 4.0, 2.0, 4.0, 1.0, 3.0


def divide(a, b):
    """a / b as IEEE 754 doubles divide (Python raises on b == 0)."""
    if b != 0.0:
        return a / b
    if a == 0.0 or math.isnan(a):
        return math.nan
    return math.copysign(math.inf, a) * math.copysign(1.0, b)


def idm(speed, lead_speed, gap):
    desired = S0 + speed * HEADWAY + speed * (speed - lead_speed) / (2.0 * math.sqrt(ALPHA * B))
    interaction = divide(desired, gap - LENGTH)
    a = ALPHA * (1.0 - (speed / V0) ** DELTA - interaction * interaction)
    return -math.inf if math.isnan(a) else a


def enhanced_ttc(rng, rate, relative_acceleration):
    if relative_acceleration == 0.0:
        if rate >= 0.0:
            return None
        ettc = rng / -rate
    else:
        discriminant = rate * rate - 2.0 * relative_acceleration * rng
        if discriminant < 0.0:
            return None
        ettc = (-rate - math.sqrt(discriminant)) / relative_acceleration
    return ettc if ettc >= 0.0 and math.isfinite(ettc) else None


def normalised_ettc(rng, rate, relative_acceleration):
    t = enhanced_ttc(rng, rate, relative_acceleration)
    return 1.0 if t is None else min(t / U_I, 1.0)


def clamp(x, low, high):
    return max(low, min(high, x))


def run(rng, rate):
    """(accident, mnpETTC) of the IDM after a cut-in at (R, R')."""
    lead_speed = INITIAL_SPEED + rate
    speed = INITIAL_SPEED
    gap = rng
    mnp = 1.0
    if gap <= ACCIDENT_GAP:
        return True, 0.0
    for _ in range(STEPS):
        a = clamp(idm(speed, lead_speed, gap), *ACCELERATION)
        # The authors' speed update: no acceleration past a bound the
        # speed already sits on; the speed is clipped after the step.
        if (speed >= SPEED[1] and a > 0.0) or (speed <= SPEED[0] and a < 0.0):
            a = 0.0
        mnp = min(mnp, normalised_ettc(gap, lead_speed - speed, -a))
        gap += (lead_speed - speed) * DT - a * DT * DT / 2.0
        speed += a * DT
        speed = clamp(speed, *SPEED)
        if gap <= ACCIDENT_GAP:
            return True, 0.0
    return False, mnp


def answer(message):
    sys.stdout.write(json.dumps(message) + "\n")
    sys.stdout.flush()


def main(cases):
    """Answers the protocol on stdin and stdout for `cases`, the names of
    the case files whose program this is."""
    for line in sys.stdin:
        request = json.loads(line)
        kind = request.get("type")
        if kind == "hello":
            answer({"type": "hello", "protocol": 2, "name": NAME,
                    "cases": {case: ["episode"] for case in cases}})
        elif kind == "reset":
            answer({"type": "ready"})
        elif kind == "episode":
            scenario = request["scenario"]
            accident, mnp = run(float(scenario["range"]), float(scenario["range_rate"]))
            answer({"type": "outcome", "event": accident, "criticality": mnp})
        else:
            answer({"type": "error", "message": "cutin_idm.py drives episodes only"})


if __name__ == "__main__":
    main(sys.argv[1:] or ["cut-in-py"])

#!/usr/bin/env python3
"""A held-out vehicle under test for tslg: Gipps' car-following model
(Gipps 1981, "A behavioural car-following model for computer simulation"),
in step mode on the cut-in case, with a driver's reaction time. No tslg
test, default or library was tuned on it; it is the vehicle the adaptive
campaigns are measured on without having seen it (docs/adaptive-design.md).
Standard library only.

    tslg validate --vut-exec gipps="python3 examples/python/gipps_vut.py"
    tslg-worker --vut-exec gipps="python3 examples/python/gipps_vut.py"

Gipps' speed after a reaction time tau is the smaller of a free-road and a
safe-braking speed:

    v_free = v + 2.5 a tau (1 - v/V) sqrt(0.025 + v/V)
    v_safe = b tau + sqrt(b^2 tau^2 - b (2 (gap - s0) - v tau - v_l^2 / b_lead))

(b < 0 the driver's braking, b_lead < 0 the braking the driver expects of
the leader). The vehicle commands the acceleration that reaches that speed
in tau, (min(v_free, v_safe) - v) / tau, clipped to the world's bounds, and
holds it for tau: it sees and reacts once per reaction time, not at every
simulation step. The protocol (one JSON object per line on stdin and
stdout) is docs/vut-protocol.md.
"""
import json
import math
import sys

PARAMS = dict(
    a=2.0,        # maximum acceleration (m/s^2)
    b=-3.0,       # the driver's most severe braking (m/s^2)
    b_lead=-3.5,  # what the driver expects of the leader (m/s^2)
    V=18.0,       # desired speed (m/s), the cut-in IDM's v0
    s0=2.0,       # standstill gap (m)
    tau=0.5,      # reaction time (s)
)


def gipps_speed(p, speed, lead_speed, gap):
    """The speed Gipps' driver aims at one reaction time ahead."""
    free = speed + 2.5 * p["a"] * p["tau"] * (1.0 - speed / p["V"]) * math.sqrt(
        max(0.025 + speed / p["V"], 0.0))
    b, tau = p["b"], p["tau"]
    inside = b * b * tau * tau - b * (
        2.0 * (gap - p["s0"]) - speed * tau - lead_speed * lead_speed / p["b_lead"])
    safe = b * tau + math.sqrt(inside) if inside > 0.0 else 0.0
    return max(min(free, safe), 0.0)


def respond(message, state):
    """The reply to one message; `state` is what this test remembers."""
    kind = message["type"]
    if kind == "hello":
        return {"type": "hello", "protocol": 2, "name": "gipps",
                "cases": {"cut-in": ["step"]}}
    if kind == "reset":
        if message["case"] != "cut-in" or message["mode"] != "step":
            return {"type": "error",
                    "message": f"cannot drive {message['case']} in {message['mode']} mode"}
        state.clear()  # nothing from the last test survives
        state.update(limits=message["world"]["acceleration"], held=None, until=0.0)
        return {"type": "ready"}
    if kind == "step":
        time = message["time"]
        if state["held"] is None or time >= state["until"] - 1e-9:
            lead = next(v for v in message["vehicles"] if "gap" in v)
            speed = message["ego"]["speed"]
            target = gipps_speed(PARAMS, speed, lead["speed"], lead["gap"])
            low, high = state["limits"]
            state["held"] = min(max((target - speed) / PARAMS["tau"], low), high)
            state["until"] = time + PARAMS["tau"]
        return {"type": "control", "acceleration": state["held"]}
    return {"type": "error", "message": f"unexpected message {kind}"}


def main():
    state = {}
    for line in sys.stdin:  # the worker closes stdin to stop us
        print(json.dumps(respond(json.loads(line), state)), flush=True)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""An external vehicle under test for tslg: the IDM of SPEC section 4, in
step mode, for the cut-in and car-following cases. Standard library only.

    tslg-worker --vut-exec py-idm="python3 examples/python/idm_vut.py"

then start a campaign with "vut": {"external": "py-idm"}. The protocol
(one JSON object per line on stdin and stdout) is docs/vut-protocol.md.

Options, for trying the service with a vehicle that is not
bit-reproducible (docs/statistics.md, "Noisy vehicles"):

    --noise SIGMA        add Gaussian noise (m/s^2) to every command, from
                         fresh entropy each run; hello then says
                         "deterministic": false
    --brake-harder A     brake A m/s^2 harder than the IDM whenever it brakes
                         (a program that differs from the others')

And for trying what an adaptive campaign cannot see (docs/statistics.md,
"Adaptive campaigns"):

    --blind R0,R1,D0,D1  a perception bug: when the lead first appears at a
                         gap in [R0, R1] m closing at a range rate (lead
                         minus own speed) in [D0, D1] m/s, the program does
                         not see it for the rest of the test and accelerates
                         as on an empty road. The scenarios where that ends in an
                         accident are an island of failures that no other
                         failure or near miss leads to.
"""
import argparse
import json
import math
import random
import sys

# The built-in IDM's parameters: the cut-in calibration (paper Table III)
# and the car-following case's highway values (v0 36 m/s, no length).
PARAMS = {
    "cut-in": dict(alpha=2.0, v0=18.0, delta=4.0, s0=2.0, length=4.0, headway=1.0, b=3.0),
    "car-following": dict(alpha=2.0, v0=36.0, delta=4.0, s0=2.0, length=0.0, headway=1.0, b=3.0),
}


def idm(p, speed, lead_speed, gap):
    """a = alpha (1 - (v/v0)^delta - (s*/(R - L))^2), evaluated as written."""
    desired = p["s0"] + speed * p["headway"] + speed * (speed - lead_speed) / (
        2.0 * math.sqrt(p["alpha"] * p["b"]))
    if gap == p["length"]:
        return -math.inf  # no room at all: brake as hard as allowed
    interaction = desired / (gap - p["length"])
    return p["alpha"] * (1.0 - (speed / p["v0"]) ** p["delta"] - interaction * interaction)


# The plain IDM: no noise, no harder braking, no blind spot.
PLAIN = argparse.Namespace(noise=0.0, brake_harder=0.0, entropy=None, blind=None)


def blind_to(window, gap, range_rate):
    """Whether the perception bug hides a lead first seen at `gap`, `range_rate`."""
    if window is None:
        return False
    r0, r1, d0, d1 = window
    return r0 <= gap <= r1 and d0 <= range_rate <= d1


def respond(message, state, options=PLAIN):
    """The reply to one message; `state` is what this test remembers."""
    kind = message["type"]
    if kind == "hello":
        return {"type": "hello", "protocol": 1, "name": "py-idm",
                "cases": {case: ["step"] for case in PARAMS},
                "deterministic": options.noise == 0.0}
    if kind == "reset":
        if message["case"] not in PARAMS or message["mode"] != "step":
            return {"type": "error", "message": f"cannot drive {message['case']} in {message['mode']} mode"}
        state.clear()  # nothing from the last test survives
        state.update(PARAMS[message["case"]], limits=message["world"]["acceleration"])
        return {"type": "ready"}
    if kind == "step":
        lead = next(v for v in message["vehicles"] if "gap" in v)
        speed = message["ego"]["speed"]
        if "blind" not in state:  # the test's first step
            state["blind"] = blind_to(options.blind, lead["gap"], lead["speed"] - speed)
        if state["blind"]:
            a = state["limits"][1]  # an empty road ahead: as fast as allowed
        else:
            a = idm(state, speed, lead["speed"], lead["gap"])
        if a < 0.0:
            a -= options.brake_harder
        if options.noise > 0.0:
            a += options.entropy.gauss(0.0, options.noise)
        low, high = state["limits"]
        return {"type": "control", "acceleration": min(max(a, low), high)}
    return {"type": "error", "message": f"unexpected message {kind}"}


def window(text):
    """`R0,R1,D0,D1`, each pair increasing."""
    try:
        r0, r1, d0, d1 = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not four numbers R0,R1,D0,D1")
    if not (r0 <= r1 and d0 <= d1):
        raise argparse.ArgumentTypeError(f"{text!r}: need R0 <= R1 and D0 <= D1")
    return (r0, r1, d0, d1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise", type=float, default=0.0, metavar="SIGMA")
    parser.add_argument("--brake-harder", type=float, default=0.0, metavar="A")
    parser.add_argument("--blind", type=window, default=None, metavar="R0,R1,D0,D1")
    options = parser.parse_args()
    if options.noise < 0.0 or options.brake_harder < 0.0:
        parser.error("--noise and --brake-harder must be >= 0")
    options.entropy = random.Random()  # seeded from os.urandom
    state = {}
    for line in sys.stdin:  # the worker closes stdin to stop us
        print(json.dumps(respond(json.loads(line), state, options)), flush=True)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""The cut-in scenario simulated in SUMO, the open traffic simulator
(https://eclipse.dev/sumo), as the program of a user-defined case
(examples/cases/cut-in-sumo.toml) or as an external vehicle of the built-in
cut-in case in episode mode.

A background vehicle (the leader) cuts in at range R (m, bumper to bumper)
and range rate R' (m/s) ahead of the vehicle under test, which drives at
20 m/s and follows it for 10 s under one of SUMO's car-following models
(SUMO's IDM by default, or any model SUMO names: Krauss, ACC, CACC, ...)
on a one-lane road, in steps of 0.1 s. The leader keeps its speed (SUMO's
safety checks off for it). The event is an accident: the bumper gap at 0 m
or below at a step. The criticality is the minimum over the run of the
time to collision at constant speeds over 100 s (mnpTTC, 0 for an accident).

It speaks tslg's external-vehicle protocol in episode mode
(docs/vut-protocol.md). It runs SUMO in its own process through libsumo
(PyPI `eclipse-sumo` and `libsumo`, which scripts/install-test-deps puts
in target/sumo-venv), one simulation for all episodes: each episode adds
its two vehicles on a road of their own, steps, and removes them.

    cutin_sumo.py [--model IDM] [--case NAME ...]
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import libsumo as traci
import sumo

INITIAL_SPEED = 20.0  # the vehicle under test at the cut-in; the leader at v + R'
STEP = 0.1
STEPS = 100
LENGTH = 5.0
U_I = 100.0  # TTC normalisation (s)


def network(folder):
    """A straight one-lane road of 3 km, made by SUMO's netconvert."""
    nodes = os.path.join(folder, "road.nod.xml")
    edges = os.path.join(folder, "road.edg.xml")
    net = os.path.join(folder, "road.net.xml")
    with open(nodes, "w") as f:
        f.write('<nodes><node id="a" x="0" y="0"/><node id="b" x="3000" y="0"/></nodes>')
    with open(edges, "w") as f:
        f.write('<edges><edge id="road" from="a" to="b" numLanes="1" speed="50"/></edges>')
    netconvert = os.path.join(sumo.SUMO_HOME, "bin", "netconvert")
    subprocess.run([netconvert, "-n", nodes, "-e", edges, "-o", net, "--no-warnings"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return net


class Simulation:
    def __init__(self, model):
        self.folder = tempfile.mkdtemp(prefix="tslg-sumo-")
        net = network(self.folder)
        types = os.path.join(self.folder, "types.add.xml")
        with open(types, "w") as f:
            # The follower: the paper's IDM calibration in SUMO's model
            # (accel 2, decel 3, headway 1 s, standstill gap 2 m, desired
            # speed 18 m/s, delta 4); the leader: a plain car.
            f.write(f"""<additional>
  <vType id="follower" carFollowModel="{model}" accel="2" decel="3" emergencyDecel="9"
         tau="1" minGap="2" length="{LENGTH}" maxSpeed="40" desiredMaxSpeed="18"
         speedFactor="1" speedDev="0"/>
  <vType id="leader" accel="3" decel="9" emergencyDecel="9" length="{LENGTH}" maxSpeed="50"
         speedFactor="1" speedDev="0"/>
  <route id="r" edges="road"/>
</additional>""")
        traci.start(["sumo", "-n", net, "-a", types, "--step-length", str(STEP),
                     "--no-step-log", "--no-warnings", "--collision.action", "none",
                     "--begin", "0"])
        self.episode = 0

    def run(self, rng, rate):
        """(accident, mnpTTC) of the follower after a cut-in at (R, R')."""
        self.episode += 1
        follower, leader = f"f{self.episode}", f"l{self.episode}"
        lead_speed = INITIAL_SPEED + rate
        start = 100.0
        # Inserted at rest, then placed and given their speeds: SUMO's own
        # insertion checks would refuse the closest cut-ins.
        traci.vehicle.add(follower, "r", typeID="follower", departPos="0", departSpeed="0")
        traci.vehicle.add(leader, "r", typeID="leader", departPos="50", departSpeed="0")
        for v in (follower, leader):
            # Inserted where the scenario says, whatever SUMO's insertion
            # checks would say; the leader holds its speed.
            traci.vehicle.setSpeedMode(v, 0)
        traci.vehicle.setSpeed(leader, max(lead_speed, 0.0))
        traci.simulationStep()
        traci.vehicle.setSpeedMode(follower, 31)
        traci.vehicle.moveTo(follower, "road_0", start)
        traci.vehicle.moveTo(leader, "road_0", start + rng + LENGTH)
        traci.vehicle.setPreviousSpeed(follower, INITIAL_SPEED)
        traci.vehicle.setPreviousSpeed(leader, max(lead_speed, 0.0))
        accident, mnp = rng <= 0.0, 1.0
        step = 0
        while not accident and step < STEPS:
            traci.simulationStep()
            step += 1
            gap = (traci.vehicle.getLanePosition(leader) - LENGTH
                   - traci.vehicle.getLanePosition(follower))
            closing = traci.vehicle.getSpeed(follower) - traci.vehicle.getSpeed(leader)
            if gap <= 0.0:
                accident = True
            elif closing > 0.0:
                mnp = min(mnp, min(gap / closing / U_I, 1.0))
        for v in (follower, leader):
            traci.vehicle.remove(v)
        traci.simulationStep()
        return accident, 0.0 if accident else mnp


def answer(message):
    sys.stdout.write(json.dumps(message) + "\n")
    sys.stdout.flush()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--model", default="IDM", help="SUMO's car-following model")
    parser.add_argument("--case", action="append", default=[],
                        help="a case it drives (default: cut-in-sumo and cut-in)")
    args = parser.parse_args()
    cases = args.case or ["cut-in-sumo", "cut-in"]
    simulation = None
    for line in sys.stdin:
        request = json.loads(line)
        kind = request.get("type")
        if kind == "hello":
            answer({"type": "hello", "protocol": 2, "name": f"sumo-{args.model.lower()}",
                    "cases": {case: ["episode"] for case in cases}})
        elif kind == "reset":
            answer({"type": "ready"})
        elif kind == "episode":
            if simulation is None:
                simulation = Simulation(args.model)
            scenario = request["scenario"]
            accident, mnp = simulation.run(float(scenario["range"]), float(scenario["range_rate"]))
            answer({"type": "outcome", "event": accident, "criticality": mnp})
        else:
            answer({"type": "error", "message": "cutin_sumo.py drives episodes only"})


if __name__ == "__main__":
    main()

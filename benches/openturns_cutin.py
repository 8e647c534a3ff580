"""The cut-in NDD estimate as a user of OpenTURNS would compute it.

The model is the cut-in of tslg's `paper-code` preset with the IDM, written
in plain Python (docs/models.md: 10 steps of 1 s, a in [-3, 3], v in
[0, 40], the speed clipped after the step, an accident at a range <= 0);
the input distribution is tslg's built-in exposure, read from the CSV the
benchmark writes (range, range rate, probability per grid cell).
OpenTURNS's ProbabilitySimulationAlgorithm samples it by Monte Carlo until
the estimate's coefficient of variation is at most beta / z, the same
precision as tslg's relative half-width beta at confidence z.

Usage: python openturns_cutin.py EXPOSURE.csv BETA Z SEED
Prints one JSON line: tests, estimate, seconds, and the exact P(A) of this
model on the grid (the benchmark checks it against tslg's).
"""

import json
import math
import sys
import time

import openturns as ot

SQRT_AB2 = 2.0 * math.sqrt(2.0 * 3.0)


def accident(range_, range_rate):
    """1.0 when the IDM crashes after a cut-in at (range, range rate)."""
    lead = 20.0 + range_rate
    v = 20.0
    gap = range_
    if gap <= 0.0:
        return 1.0
    for _ in range(10):
        desired = 2.0 + v * 1.0 + v * (v - lead) / SQRT_AB2
        spacing = gap - 4.0
        if spacing == 0.0:
            a = -math.inf
        else:
            interaction = desired / spacing
            a = 2.0 * (1.0 - (v / 18.0) ** 4 - interaction * interaction)
        a = min(max(a, -3.0), 3.0)
        if (v >= 40.0 and a > 0.0) or (v <= 0.0 and a < 0.0):
            a = 0.0
        gap += (lead - v) * 1.0 - a * 1.0 * 1.0 / 2.0
        v = min(max(v + a * 1.0, 0.0), 40.0)
        if gap <= 0.0:
            return 1.0
    return 0.0


def main():
    path, beta, z, seed = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
    points, weights = [], []
    with open(path) as f:
        next(f)
        for line in f:
            r, rr, p = (float(x) for x in line.split(","))
            if p > 0.0:
                points.append([r, rr])
                weights.append(p)
    exact = sum(p * accident(r, rr) for (r, rr), p in zip(points, weights)) / sum(weights)
    ot.RandomGenerator.SetSeed(seed)
    exposure = ot.UserDefined(ot.Sample(points), ot.Point(weights))
    model = ot.PythonFunction(2, 1, lambda x: [accident(x[0], x[1])])
    x = ot.RandomVector(exposure)
    y = ot.CompositeRandomVector(model, x)
    event = ot.ThresholdEvent(y, ot.Greater(), 0.5)
    algorithm = ot.ProbabilitySimulationAlgorithm(event, ot.MonteCarloExperiment())
    algorithm.setMaximumCoefficientOfVariation(beta / z)
    algorithm.setMaximumOuterSampling(10**9)
    algorithm.setBlockSize(1000)
    started = time.perf_counter()
    algorithm.run()
    seconds = time.perf_counter() - started
    result = algorithm.getResult()
    tests = result.getOuterSampling() * result.getBlockSize()
    print(json.dumps({"tests": tests, "estimate": result.getProbabilityEstimate(),
                      "seconds": seconds, "exact": exact}))


if __name__ == "__main__":
    main()

"""Research prototype (issue 21, part 3): search, then estimate. A library
stage of s0 tests, then a deterministic search that tests every untested
neighbour of a seed (a failing cell, or a tested cell with mnpETTC <= c*)
whose exposure exceeds tau times the failure mass found so far, until no
seed has such a neighbour; an estimation stage of n_est tests follows. It
prints the tests used and the share of the failure mass the search found.

    python3 scripts/research/search_prototype.py builtin-cells.csv table-cells.csv
"""
import sys, numpy as np
from adaptive_prototype import Case, q_library, Z
def search(case, vut, lib, seed, c_star, tau=1e-4, s0=100, n_est=100, eps=0.1):
    rng = np.random.default_rng(seed)
    A = case.A(vut); C = case.C(vut); P = case.P
    q = q_library(case, case.V(lib), eps)
    tested = np.zeros(case.N, bool)
    tested[rng.choice(case.N, size=s0, p=q)] = True
    tests = s0
    while True:
        seeds = tested & (A | (C <= c_star))
        frontier = case.dilate(seeds, 1) & ~tested & (P > tau * P[tested & A].sum())
        if not frontier.any(): break
        tested |= frontier; tests += frontier.sum()
    mu = P[A].sum(); found = P[A & tested].sum()
    return tests + n_est, found / mu
for path in sys.argv[1:]:
    case = Case(path)
    print(path)
    for lib, vut in [('idm','idm'),('fvdm','fvdm'),('fvdm','idm'),('idm','fvdm'),('idm','switching-acc'),('idm','acc-aeb')]:
        mu = case.P[case.A(vut)].sum(); ndd = Z*Z*(1-mu)/(0.04*mu)
        for cs in [0.02, 0.05]:
            rs = [search(case, vut, lib, s, cs) for s in range(20)]
            t = np.median([r[0] for r in rs]); f = np.min([r[1] for r in rs])
            print(f'  {lib}->{vut:14} c*={cs:.2f} tests {t:6.0f} NDD {ndd:7.0f} ratio {ndd/t:6.1f} failure mass found (worst of 20) {f:.3f}')

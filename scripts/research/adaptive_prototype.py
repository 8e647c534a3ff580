"""Research prototype (issue 21, part 3): staged adaptive importance sampling
on the cut-in grid, from the per-cell table that
`cargo run --release -p tslg-method --example cutin_cells -- builtin cells.csv`
writes. Not part of the product; docs/adaptive-design.md gives what it measured.

    python3 scripts/research/adaptive_prototype.py cells.csv '{"adaptive": false}' 100
    python3 scripts/research/adaptive_prototype.py cells.csv '{"n_min": 1000, "rho": 0.1}' 50
"""
import csv, sys, numpy as np
Z = 1.6448536269514722

def load(path):
    rows = list(csv.DictReader(open(path)))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0].keys()}

class Case:
    def __init__(self, path):
        d = load(path)
        self.P = d['p'] / d['p'].sum()
        rs = np.unique(d['r']); rrs = np.unique(d['rr'])
        self.shape = (len(rs), len(rrs))
        assert np.all(np.searchsorted(rs, d['r']) * len(rrs) + np.searchsorted(rrs, d['rr']) == np.arange(len(d['r'])))
        self.N = len(self.P); self.d = d
    def A(self, v): return self.d['a_' + v] > 0.5
    def C(self, v): return self.d['c_' + v]
    def V(self, lib): return self.d['v_' + lib]
    def dilate(self, mask, rad):
        g = mask.reshape(self.shape); out = g.copy()
        X, Y = self.shape
        for dx in range(-rad, rad + 1):
            for dy in range(-rad, rad + 1):
                src = g[max(0, -dx):X - max(0, dx), max(0, -dy):Y - max(0, dy)]
                out[max(0, dx):X - max(0, -dx), max(0, dy):Y - max(0, -dy)] |= src
        return out.ravel()

def q_library(case, V, eps, outside='uniform'):
    inl = V > 0; q = np.zeros(case.N)
    q[inl] = (1 - eps) * V[inl] / V[inl].sum()
    out = ~inl
    q[out] = eps / out.sum() if outside == 'uniform' else eps * case.P[out] / case.P[out].sum()
    return q

def campaign(case, vut, lib, seed, beta=0.2, eps=0.1, n_min=100, min_events=10, stage=100,
             growth=1.0, a_lib=0.5, a_fill=0.4, a_p=0.1, rad=1, lam=1.0, max_tests=300000,
             outside='uniform', adaptive=True, rho=0.0):
    rng = np.random.default_rng(seed)
    A = case.A(vut); P = case.P; C = case.C(vut)
    qlib = q_library(case, case.V(lib), eps, outside)
    tested = np.zeros(case.N, bool); failed = np.zeros(case.N, bool)
    sw = swx = sw2 = sw2x = sw2x2 = 0.0
    n = 0; events = 0; k = 0; size = stage
    while n < max_tests:
        if not adaptive:
            q = qlib
        elif failed.any() or rho > 0:
            seeds = failed.copy()
            if rho > 0 and (tested & ~failed).any():
                ct = C[tested & ~failed]
                thr = np.quantile(ct, rho)
                seeds |= tested & (C <= thr)
            region = case.dilate(seeds, rad) & ~(tested & ~failed)
            r = P * region
            q = a_lib * qlib + a_fill * r / r.sum() + a_p * P if r.sum() > 0 else (a_lib + a_fill) * qlib + a_p * P
        else:
            q = (1 - a_p) * qlib + a_p * P
        q = q / q.sum()
        m = int(min(size, max_tests - n))
        cells = rng.choice(case.N, size=m, p=q)
        y = A[cells]; x = np.where(y, P[cells] / q[cells], 0.0)
        l = lam ** k
        cw = sw + l * np.arange(1, m + 1); cwx = swx + l * np.cumsum(x)
        cw2 = sw2 + l * l * np.arange(1, m + 1); cw2x = sw2x + l * l * np.cumsum(x); cw2x2 = sw2x2 + l * l * np.cumsum(x * x)
        ce = events + np.cumsum(y & (x > 0)); cn = n + np.arange(1, m + 1)
        mean = cwx / cw
        var = (cw2x2 - 2 * mean * cw2x + mean * mean * cw2) / (cw * cw) * cn / np.maximum(cn - 1, 1)
        hw = Z * np.sqrt(np.maximum(var, 0))
        ok = (cn >= n_min) & (ce >= min_events) & (mean > 0) & (hw <= beta * mean)
        if ok.any():
            j = int(np.argmax(ok))
            return dict(tests=int(cn[j]), estimate=mean[j], low=mean[j] - hw[j], high=mean[j] + hw[j], stages=k + 1)
        sw, swx, sw2, sw2x, sw2x2 = cw[-1], cwx[-1], cw2[-1], cw2x[-1], cw2x2[-1]
        n += m; events = int(ce[-1])
        tested[cells] = True; failed[cells] |= y
        k += 1; size = size * growth
    return dict(tests=n, estimate=swx / sw if sw else 0, low=0, high=0, stages=k)

def study(case, pairs, seeds, **kw):
    out = []
    for lib, vut in pairs:
        mu = case.P[case.A(vut)].sum()
        ndd = Z * Z * (1 - mu) / (0.04 * mu)
        rs = [campaign(case, vut, lib, s, **kw) for s in range(seeds)]
        cov = np.mean([r['low'] <= mu <= r['high'] for r in rs])
        med = np.median([r['tests'] for r in rs])
        out.append((lib, vut, cov, med, ndd / med, np.mean([r['estimate'] for r in rs]) / mu - 1))
    return out

if __name__ == '__main__':
    case = Case(sys.argv[1])
    pairs = [('idm', 'idm'), ('fvdm', 'fvdm'), ('fvdm', 'idm'), ('idm', 'fvdm'), ('idm', 'switching-acc'), ('idm', 'acc-aeb')]
    import json
    kw = json.loads(sys.argv[2]) if len(sys.argv) > 2 else {}
    seeds = int(sys.argv[3]) if len(sys.argv) > 3 else 100
    for lib, vut, cov, med, ratio, bias in study(case, pairs, seeds, **kw):
        print(f'{lib:5} -> {vut:14} coverage {cov:.3f}  median {med:8.0f}  NDD/median {ratio:7.1f}  bias {bias:+.3f}')

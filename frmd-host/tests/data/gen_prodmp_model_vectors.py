# Generates frmd-host/tests/data/prodmp_model_vectors.json: a pure-Python model of mp_pytorch 0.1.4
# ProDMP semantics (NOT mp_pytorch output), covering options the 18 reference cases do not:
# pre_compute_length_factor 3/4, per-basis weights_scale, disable_weights/disable_goal, b = 1/2 with
# delays and init times, and times up to the end of the pre-computed range (extrapolation).
# Run: python3 gen_prodmp_model_vectors.py  (writes the JSON next to this script)
import json, math, random

def linspace(a, b, n, i):
    if n <= 1: return a
    step = (b - a) / (n - 1)
    return a + step * i if i < n // 2 else b - step * (n - 1 - i)

def lerp(a, b, w):
    return a + w * (b - a) if abs(w) < 0.5 else b - (b - a) * (1 - w)

def build(cfg):
    tau, delay, ap, nb = cfg['tau'], cfg['delay'], cfg['alpha_phase'], cfg['num_basis']
    L, alpha, dt = cfg['pre_compute_length_factor'], cfg['alpha'], cfg['dt']
    if nb > 1:
        o = cfg['num_basis_outside']; h = tau / (nb - 2 * o - 1)
        ct = [linspace(-o * h + delay, o * h + tau + delay, nb, i) for i in range(nb)]
        ct.append(ct[-1] + (ct[1] - ct[0]))
        cp = [math.exp(-ap * ((t - delay) / tau)) for t in ct]
        d = [cp[i + 1] - cp[i] for i in range(nb)]
        if nb == 2: d[-1] *= 2
        centers = cp[:nb]
    else:
        centers = [math.exp(-ap * ((delay + 0.5 * tau - delay) / tau))]; d = [1.0]
    bw = [cfg['basis_bandwidth_factor'] / (x * x) for x in d]
    sdt = dt / tau
    n = L * round(1 / sdt) + 1
    s = [linspace(0, L, n, k) for k in range(n)]
    def basis(x):
        v = [math.exp(-((x - c) ** 2 * b) / 2) for c, b in zip(centers, bw)]
        if nb > 1:
            tot = sum(v); v = [a / tot for a in v]
        return v
    P1 = [0.0] * nb; P2 = [0.0] * nb; prev = None
    B = []; dB = []; Y = []
    for k, sk in enumerate(s):
        t = sk * tau + delay
        x = math.exp(-ap * max((t - delay) / tau, 0))
        e = math.exp(alpha * sk / 2)
        phi = basis(x)
        d1 = [sk * e * x * p for p in phi]; d2 = [e * x * p for p in phi]
        if prev is not None:
            ds = sk - s[k - 1]
            for j in range(nb):
                P1[j] += ds * (prev[0][j] + d1[j]) / 2
                P2[j] += ds * (prev[1][j] + d2[j]) / 2
        prev = (d1, d2)
        y1 = math.exp(-0.5 * alpha * sk); y2 = sk * y1
        dy1 = -0.5 * alpha * y1; dy2 = -0.5 * alpha * y2 + y1
        q1 = (0.5 * alpha * sk - 1) * math.exp(0.5 * alpha * sk) + 1
        q2 = 0.5 * alpha * (math.exp(0.5 * alpha * sk) - 1)
        B.append([P2[j] * y2 - P1[j] * y1 for j in range(nb)] + [q2 * y2 - q1 * y1])
        dB.append([P2[j] * dy2 - P1[j] * dy1 for j in range(nb)] + [q2 * dy2 - q1 * dy1])
        Y.append((y1, y2, dy1, dy2))
    colmax = [max(r[j] for r in B) for j in range(nb + 1)]
    ws = cfg['weights_scale']; ws = ws if isinstance(ws, list) else [ws] * nb
    scale = [1 / m for m in colmax] if cfg['auto_scale_basis'] else [1.0] * (nb + 1)
    scale = [scale[j] * ws[j] for j in range(nb)] + [scale[nb] * cfg['goal_scale']]
    def look(t):
        sc = max((t - delay) / tau, 0)
        assert sc <= L
        idx = sc / sdt
        i0 = min(max(math.floor(idx), 0), n - 2); w = idx - i0
        row = lambda tab: [lerp(a, b, w) for a, b in zip(tab[i0], tab[i0 + 1])]
        return row(B), row(dB), row(Y)
    return dict(n=n, centers=centers, bw=bw, colmax=colmax, scale=scale, look=look)

def decode(cfg, m, params, t0, y0, v0, times):
    nb, nd, tau = cfg['num_basis'], cfg['num_dof'], cfg['tau']
    B0, dB0, (a1, a2, da1, da2) = m['look'](t0)
    det = a1 * da2 - a2 * da1
    pos, vel, H = [], [], []
    for t in times:
        Bt, dBt, (y1, y2, dy1, dy2) = m['look'](t)
        xi1 = da2 / det * y1 - da1 / det * y2; xi2 = a1 / det * y2 - a2 / det * y1
        dxi1 = da2 / det * dy1 - da1 / det * dy2; dxi2 = a1 / det * dy2 - a2 / det * dy1
        h = [-xi1 * B0[j] - xi2 * dB0[j] + Bt[j] for j in range(nb + 1)]
        dh = [-dxi1 * B0[j] - dxi2 * dB0[j] + dBt[j] for j in range(nb + 1)]
        H.append(h)
        pr, vr = [], []
        for d in range(nd):
            th = params[d * (nb + 1):(d + 1) * (nb + 1)]
            p = xi1 * y0[d] + xi2 * v0[d] * tau + sum(h[j] * m['scale'][j] * th[j] for j in range(nb + 1))
            v = dxi1 * y0[d] + dxi2 * v0[d] * tau + sum(dh[j] * m['scale'][j] * th[j] for j in range(nb + 1))
            if cfg['relative_goal']:
                p += h[nb] * y0[d]; v += dh[nb] * y0[d]
            pr.append(p); vr.append(v / tau)
        pos.append(pr); vel.append(vr)
    return pos, vel, H

rng = random.Random(7)
cases = []
for c in range(14):
    nb = [1, 2, 3, 7, 12][c % 5]
    out = 1 if (nb >= 7 and c % 3 == 0) else 0
    L = [6, 3, 4][c % 3]
    cfg = dict(mp_type='prodmp', phase_generator='ExpDecayPhaseGenerator', num_dof=rng.randint(1, 4),
               tau=rng.choice([0.5, 1.0, 2.3, 0.37]), delay=rng.choice([0.0, 0.15, 0.4]),
               alpha_phase=rng.choice([1.5, 2.0, 3.0]), num_basis=nb,
               basis_bandwidth_factor=rng.choice([2.0, 3.0, 6.0]), num_basis_outside=out,
               dt=rng.choice([0.01, 0.007, 0.025, 0.013]), alpha=rng.choice([10.0, 25.0, 40.0]),
               pre_compute_length_factor=L,
               weights_scale=[round(rng.uniform(0.5, 2), 3) for _ in range(nb)] if c % 2 else 1.0,
               goal_scale=rng.choice([1.0, 0.5, 2.0]), relative_goal=bool(c % 2), auto_scale_basis=c % 4 == 1,
               disable_weights=c == 5, disable_goal=c == 8, learn_tau=False, learn_delay=False, dtype='float64')
    m = build(cfg)
    nd = cfg['num_dof']
    full = [rng.uniform(-10, 10) for _ in range(nd * (nb + 1))]
    if cfg['disable_weights']:
        for d in range(nd):
            for j in range(nb): full[d * (nb + 1) + j] = 0.0
        stored = [full[d * (nb + 1) + nb] for d in range(nd)]
    elif cfg['disable_goal']:
        for d in range(nd): full[d * (nb + 1) + nb] = 0.0
        stored = [full[d * (nb + 1) + j] for d in range(nd) for j in range(nb)]
    else:
        stored = full
    t0 = rng.choice([0.0, 0.1, cfg['delay'] + 0.05 * cfg['tau']])
    y0 = [rng.uniform(-1, 1) for _ in range(nd)]; v0 = [rng.uniform(-1, 1) for _ in range(nd)]
    hi = cfg['delay'] + L * cfg['tau']
    times = sorted([rng.uniform(0, hi) for _ in range(9)] + [0.0, t0, hi - 1e-9, cfg['delay'] + cfg['tau']])
    pos, vel, H = decode(cfg, m, full, t0, y0, v0, times)
    cases.append(dict(name=f'x{c}_b{nb}_L{L}', note='pure-python cross-check', config=cfg,
                      derived=dict(num_pre_compute=m['n'], centers_phase=m['centers'], bandwidth=m['bw'],
                                   weights_goal_scale=m['scale'], pc_pos_basis_max=m['colmax']),
                      inputs=dict(params=stored, init_time=t0, init_pos=y0, init_vel=v0),
                      queries=[dict(times=times, pos=pos, vel=vel, pos_H_unscaled=H)]))
json.dump(dict(library='pure-python model', cases=cases), open(__import__('os').path.join(__import__('os').path.dirname(__file__), 'prodmp_model_vectors.json'), 'w'))
print(len(cases), 'cases')

"""The synthetic tissue of `cargo xtask synth-labels`, transcribed to NumPy (same seeds and
formulas; not checked byte for byte against the xtask's output), for machines where the
xtask is not built:

    python3 bench/synth_labels.py 128,128,128 target/synth128.npy
"""
import sys, numpy as np
M = (1 << 64) - 1
class SM:
    def __init__(s, x): s.x = x
    def next(s):
        s.x = (s.x + 0x9e3779b97f4a7c15) & M
        z = s.x
        z = ((z ^ (z >> 30)) * 0xbf58476d1ce4e5b9) & M
        z = ((z ^ (z >> 27)) * 0x94d049bb133111eb) & M
        return z ^ (z >> 31)
    def unit(s): return (s.next() >> 11) / float(1 << 53)
dims = [int(v) for v in sys.argv[1].split(",")]
rng = SM(0x766f_7872_6567)  # 'voxreg'
c = [0.5 * (d - 1.0) for d in dims]; r = [0.5 * d - 2.0 for d in dims]
seeds = []
while len(seeds) < 23:
    q = [2.0 * rng.unit() - 1.0 for _ in range(3)]
    if sum(v * v for v in q) > 0.8: continue
    s = [c[k] + q[k] * r[k] for k in range(3)]
    cell = (r[0] * r[1] * r[2] / 23.0) ** (1 / 3)
    seeds.append((s, rng.unit() * 0.25 * cell * cell))
x, y, z = np.meshgrid(*(np.arange(d, dtype=np.float64) for d in dims), indexing="ij")
q = [(p - c[k]) / r[k] for k, p in enumerate((x, y, z))]
rho = np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2)
best = np.full(x.shape, np.inf); idx = np.zeros(x.shape, np.uint8)
for i, (s, w) in enumerate(seeds):
    d = (x - s[0]) ** 2 + (y - s[1]) ** 2 + (z - s[2]) ** 2 - w
    m = d < best; best[m] = d[m]; idx[m] = i
lab = (2 + idx).astype(np.uint8)
lab[rho > 1.0 - 4.0 / min(r)] = 1
lab[rho > 1.0] = 0
np.save(sys.argv[2], lab)
print(lab.shape, len(np.unique(lab)))

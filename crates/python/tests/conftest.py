"""Shared fixtures: the repository's bundled data, the CLI binary, small synthetic volumes."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
DATA = ROOT / "data"


def cli_binary():
    """The `voxreg` command built by `cargo build --release -p voxreg-cli`, or None."""
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    exe = target / "release" / "voxreg"
    return exe if exe.is_file() else None


@pytest.fixture(scope="session")
def cli():
    exe = cli_binary()
    if exe is None:
        pytest.skip("the CLI is not built (cargo build --release -p voxreg-cli)")

    def run(*args):
        return subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)

    return run


@pytest.fixture(scope="session")
def data():
    return DATA


def ball_labels(n=20, r=6.0, split=True):
    """A ball of radius r in an n^3 volume, label 1, its x > n/2 half label 2 when split."""
    x, y, z = np.mgrid[:n, :n, :n]
    c = (n - 1) / 2
    inside = (x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2 <= r * r
    labels = inside.astype(np.uint8)
    if split:
        labels[inside & (x > c)] = 2
    return labels


def three_labels(n=16):
    """Three labels meeting along junction curves: a ball of 1 and 2 in halves, with a box
    of 3 inside it, on background 0."""
    labels = ball_labels(n, r=n / 2 - 2)
    c = n // 2
    labels[c - 2 : c + 1, c - 2 : c + 3, c - 3 : c + 3] = 3
    return labels


def synth_tissue(dims=(64, 60, 32)):
    """`cargo xtask synth-labels --dims X,Y,Z`, in numpy: 25 labels (air 0, a skin shell 1
    around 23 organs 2..24, the cells of a power diagram) meeting along junctions, uint8
    of shape (X, Y, Z). The same bytes as the xtask's (test_submeshes checks it)."""
    mask = (1 << 64) - 1
    state = [0x766F_7872_6567]

    def unit():
        state[0] = (state[0] + 0x9E37_79B9_7F4A_7C15) & mask
        z = state[0]
        z = ((z ^ (z >> 30)) * 0xBF58_476D_1CE4_E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D0_49BB_1331_11EB) & mask
        return ((z ^ (z >> 31)) >> 11) / float(1 << 53)

    c = [0.5 * (d - 1.0) for d in dims]
    r = [0.5 * d - 2.0 for d in dims]
    cell = float(np.cbrt(r[0] * r[1] * r[2] / 23.0))
    seeds = []
    while len(seeds) < 23:
        q = [2.0 * unit() - 1.0 for _ in range(3)]
        if sum(v * v for v in q) > 0.8:
            continue
        seeds.append(([c[k] + q[k] * r[k] for k in range(3)], unit() * 0.25 * cell * cell))
    p = np.meshgrid(*(np.arange(d, dtype=np.float64) for d in dims), indexing="ij")
    q = [(p[k] - c[k]) / r[k] for k in range(3)]
    rho = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    d = np.stack([(p[0] - s[0]) ** 2 + (p[1] - s[1]) ** 2 + (p[2] - s[2]) ** 2 - w for s, w in seeds])
    labels = (2 + np.argmin(d, axis=0)).astype(np.uint8)
    labels[rho > 1.0 - 4.0 / min(r)] = 1
    labels[rho > 1.0] = 0
    return labels

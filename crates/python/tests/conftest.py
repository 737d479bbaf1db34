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

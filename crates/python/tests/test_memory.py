"""Memory: uint32 labels read in place (no second copy), budgets refused up front."""

import subprocess
import sys

import numpy as np
import pytest

import voxreg
from conftest import ball_labels

# Peak resident memory growth of one run over a 224^3 volume (a small ball in it), in a
# fresh process.
PEAK = r"""
import sys
import numpy as np, voxreg

def peak():  # this process's own high-water mark (ru_maxrss also counts the parent's at fork)
    line = next(l for l in open("/proc/self/status") if l.startswith("VmHWM:"))
    return int(line.split()[1]) * 1024

dtype, order = sys.argv[1], sys.argv[2]
labels = np.full((224, 224, 224), 0, dtype=dtype, order=order)
labels[104:120, 104:120, 104:120] = 1
voxreg.regularize(np.pad(np.ones((4, 4, 4), dtype=dtype), 2), preset="papers")  # warm up
before = peak()
voxreg.regularize(labels, preset="papers", threads=1)
print(peak() - before)
"""


def peak_growth(dtype, order):
    r = subprocess.run([sys.executable, "-c", PEAK, dtype, order], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return int(r.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_uint32_labels_are_not_copied():
    copy = 224**3 * 4  # 43 MiB: what a uint32 copy of the labels takes
    grown = {order: peak_growth("uint32", order) for order in ("C", "F")}
    # The run's own work grows the peak too (about 15 MiB here), but by less than a
    # copy of the labels would.
    assert max(grown.values()) < copy, (grown, copy)
    # The control: a uint16 volume is converted, and the copy shows on top of that work.
    converted = peak_growth("uint16", "C")
    assert converted - max(grown.values()) > copy / 2, (converted, grown)


def test_strided_uint32_view_same_mesh():
    ball = ball_labels().astype(np.uint32)
    big = np.zeros((40, 20, 20), dtype=np.uint32)
    big[::2] = ball
    view = big[::2][:, ::-1][:, ::-1]  # strided, and flipped twice: the same voxels
    a = voxreg.regularize(view, preset="papers")
    b = voxreg.regularize(ball, preset="papers")
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.quads, b.quads)


def test_too_many_voxels_refused():
    absurd = np.broadcast_to(np.uint32(1), (2048, 2048, 2048))  # 2^33 voxels, no memory
    with pytest.raises(voxreg.InputError, match="exceeds the limit of 2147483648 voxels"):
        voxreg.regularize(absurd)


def test_conversion_over_budget_refused():
    big = np.broadcast_to(np.uint8(1), (1024, 1024, 1024))  # its uint32 copy: 4 GiB
    with pytest.raises(voxreg.VoxregError, match=r"uint32 copy .* needs 4.0 GiB, over the memory limit of 1.0 GiB"):
        voxreg.regularize(big, max_memory="1G")


def test_run_over_budget_refused_as_the_cli(cli, tmp_path):
    labels = ball_labels()
    with pytest.raises(voxreg.VoxregError) as e:
        voxreg.regularize(labels, max_memory=256 * 1024)
    message = str(e.value)
    assert message.startswith("labels: the regularization of its ")
    np.save(tmp_path / "ball.npy", labels)
    r = cli("--max-memory", "256k", "regularize", tmp_path / "ball.npy", "-o", tmp_path / "o.ply", "-q")
    assert r.returncode == 1 and not (tmp_path / "o.ply").exists()
    # The same figures; only the name of the input and of the option differ.
    cli_message = r.stderr.strip().removeprefix("error: ").replace(str(tmp_path / "ball.npy"), "labels")
    assert cli_message.replace("--max-memory", "max_memory=") == message
    # Within the budget, the same run goes through.
    assert len(voxreg.regularize(labels, max_memory="1G")) == len(voxreg.regularize(labels))


@pytest.mark.parametrize("bad", [0, -5, "lots", 1.5])
def test_bad_budget(bad):
    with pytest.raises(voxreg.ParameterError, match="max_memory"):
        voxreg.regularize(ball_labels(), max_memory=bad)


# A volume whose uint32 copy would not fit under a 4 GiB address-space limit, in a fresh
# process under that limit (as batch schedulers set it).
UNDER_ULIMIT = r"""
import resource
import numpy as np, voxreg

resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
labels = np.zeros((1200,) * 3, np.uint8)  # 1.6 GiB, its pages untouched
labels[600, 600, 600] = 1
try:
    voxreg.regularize(labels)
except voxreg.VoxregError as e:
    print("refused:", e)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS is Linux's")
def test_a_volume_over_the_address_space_limit_is_refused_not_killed():
    r = subprocess.run([sys.executable, "-c", UNDER_ULIMIT], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("refused:") and "memory limit" in r.stdout, r.stdout

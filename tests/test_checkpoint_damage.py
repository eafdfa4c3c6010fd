"""Damaged checkpoints: every flipped bit is refused before HDF5 reads the file, and
`--restart latest` falls back to the older checkpoint and continues bit for bit."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from conftest import BAR, parsph, parsph_batch


@pytest.fixture(scope="module")
def bar_checkpoints(tmp_path_factory):
    """The bar run to step 60 with checkpoints at steps 40 and 60, and a copy of the same run
    straight to step 80 (the reference for continuations)."""
    root = tmp_path_factory.mktemp("ckpt")
    scene = root / "bar.toml"
    scene.write_text(BAR)
    common = ["--quiet", "--set", "output.history_every=5", "--set", "output.history_interval=0.0"]
    proc = parsph(["run", scene, "--out", root / "straight", *common, "--set", "time.max_steps=80"])
    assert proc.returncode == 0, proc.stderr
    proc = parsph(["run", scene, "--out", root / "split", *common, "--set", "time.max_steps=60",
                   "--set", "output.checkpoint_every=20"])
    assert proc.returncode == 0, proc.stderr
    return root, scene, common


def _positions(path) -> dict:
    """Byte offsets inside a checkpoint worth damaging: the user block (magic, digest),
    the HDF5 superblock, every dataset's first and last value (sign bits included), the
    first bytes of each dataset's object header (datatype), and the clock attribute's
    time value."""
    raw = path.read_bytes()
    spots = {"magic": 0, "digest": 30, "digest end": 88, "padding": 300, "superblock": 512,
             "superblock end": 560, "last byte": len(raw) - 1}
    with h5py.File(path, "r") as f:
        for name in f:
            ds = f[name]
            start = ds.id.get_offset()
            size = ds.id.get_storage_size()
            item = ds.dtype.itemsize
            spots[f"{name} first value"] = start
            spots[f"{name} sign of last value"] = start + size - 1
            spots[f"{name} exponent of value 2"] = start + 2 * item - 2 if size > 3 * item else start
            spots[f"{name} header"] = ds.id.get_offset() - 64 if start > 600 else 600
        clock = f.attrs["clock"]
    where = raw.find(b'"t": ')
    assert where > 0, clock
    spots["clock time"] = where + 6
    where = raw.find(b"float64") if b"float64" in raw else raw.find(b"<f8")
    if where > 0:
        spots["float type text"] = where
    spread = np.linspace(0, len(raw) - 1, 48).astype(int)
    spots.update({f"byte {int(k)}": int(k) for k in spread})
    return spots


def test_every_flipped_bit_of_a_checkpoint_is_refused(bar_checkpoints, tmp_path):
    """Flip each bit of a sample of bytes (user block, HDF5 structure, data, attributes):
    checkpoint.verify refuses every one with one message, without opening the file with
    HDF5. Reports the counts."""
    from parsph.io import checkpoint
    from parsph.parallel.runtime import COMM

    root, _, _ = bar_checkpoints
    good = root / "split" / "checkpoints" / "step_00000060.h5"
    checkpoint.verify(str(good), COMM)  # the intact file passes
    raw = good.read_bytes()
    spots = _positions(good)
    damaged = tmp_path / "damaged.h5"
    refused, reasons = 0, {}
    for label, offset in sorted(spots.items(), key=lambda kv: kv[1]):
        for bit in range(8):
            data = bytearray(raw)
            data[offset] ^= 1 << bit
            damaged.write_bytes(bytes(data))
            with pytest.raises(ValueError) as info:
                checkpoint.verify(str(damaged), COMM)
            refused += 1
            message = str(info.value)
            assert "\n" not in message and ("damaged" in message or "not a parsph checkpoint" in message)
            reasons[message] = reasons.get(message, 0) + 1
    for cut in (len(raw) - 1, len(raw) // 2, 600, 100, 0):  # truncated files
        damaged.write_bytes(raw[:cut])
        with pytest.raises(ValueError):
            checkpoint.verify(str(damaged), COMM)
        refused += 1
    print(f"\ncheckpoint fuzz: {len(spots)} bytes x 8 bits + 5 truncations, {refused} refused, "
          f"0 accepted; {len(raw)} bytes; messages: {json.dumps(reasons)}")
    assert refused == 8 * len(spots) + 5


def test_restart_latest_skips_a_damaged_checkpoint_and_continues_bit_for_bit(bar_checkpoints, tmp_path):
    """The issue's cases: each damage to the newest checkpoint is reported, the older one is
    used, and the continued run ends equal to the straight run in every history series.
    The four refusals run one after another in one process (conftest.parsph_batch), then
    the four restarts in another."""
    import shutil

    root, scene, common = bar_checkpoints
    cases = ["sign of a velocity", "sign of a mass", "clock time", "HDF5 object header"]
    outs, newest, before = {}, {}, {}
    for k, what in enumerate(cases):
        out = outs[what] = tmp_path / f"split{k}"
        shutil.copytree(root / "split", out)
        newest[what] = out / "checkpoints" / "step_00000060.h5"
        with h5py.File(newest[what], "r") as f:
            offsets = {"sign of a velocity": f["v"].id.get_offset() + 8 * 7 + 7,
                       "sign of a mass": f["mass"].id.get_offset() + 8 * 3 + 7,
                       "HDF5 object header": f["u"].id.get_offset() - 40}
        data = bytearray(newest[what].read_bytes())
        offsets["clock time"] = data.find(b'"t": ') + 7
        data[offsets[what]] ^= 0x80 if what.startswith("sign") else 0x04
        newest[what].write_bytes(bytes(data))
        before[what] = (out / "history.h5").read_bytes()

    refusals = parsph_batch([["run", scene, "--out", outs[what], "--restart", newest[what], *common,
                              "--set", "time.max_steps=80"] for what in cases], 1, tmp_path / "refusals")
    for what, proc in zip(cases, refusals):
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, f"{what}: {proc.stderr}"
        assert "step_00000060.h5 is damaged" in proc.stderr, f"{what}: {proc.stderr}"
        assert (outs[what] / "history.h5").read_bytes() == before[what], what  # refused before anything changed

    restarts = parsph_batch([["run", scene, "--out", outs[what], "--restart", "latest", *common,
                              "--set", "time.max_steps=80"] for what in cases], 1, tmp_path / "restarts")
    for what, proc in zip(cases, restarts):
        assert proc.returncode == 0 and "Traceback" not in proc.stderr, f"{what}: {proc.stderr}"
        assert "skipping checkpoint" in proc.stdout and "is damaged" in proc.stdout, f"{what}: {proc.stdout}"
        assert "restarting from" in proc.stdout and "step_00000040.h5" in proc.stdout, f"{what}: {proc.stdout}"
        with h5py.File(root / "straight" / "history.h5", "r") as a, h5py.File(outs[what] / "history.h5", "r") as b:
            assert sorted(a) == sorted(b), what
            for name in a:
                assert np.array_equal(a[name][()], b[name][()]), (what, name)


def test_a_checkpoint_of_an_older_format_is_refused_with_a_message(bar_checkpoints, tmp_path):
    root, scene, common = bar_checkpoints
    old = tmp_path / "old.h5"
    with h5py.File(old, "w") as f:  # no user block: as parsph wrote them before
        f.attrs["format"] = 2
        f["v"] = np.zeros((40, 1))
    proc = parsph(["run", scene, "--out", tmp_path / "out", "--restart", old, *common])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "is not a parsph checkpoint" in proc.stderr, proc.stderr

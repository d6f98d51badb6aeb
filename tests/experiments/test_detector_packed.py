"""Packed person datasets (WebP images): what is read back, and what is refused."""
import json

import numpy as np
import pytest

from experiments.cli import main
from experiments.detector import evaluate
from experiments.detector.packed import LOSSLESS, pack


def shard(path, seeds, images_per_seed=2, seed=0, split="train"):
    """A file in the generator's layout: textured images (so WebP has something to lose) with one box each."""
    rng = np.random.default_rng(seed)
    n = len(seeds) * images_per_seed
    yy, xx = np.mgrid[0:256, 0:352]
    images = np.empty((n, 256, 352, 3), np.uint8)
    for i in range(n):
        base = 100 + 60 * np.sin(xx / rng.uniform(5, 20)) * np.cos(yy / rng.uniform(5, 20))
        images[i] = np.clip(base[..., None] + rng.normal(0, 8, (256, 352, 3)), 0, 255)
    boxes = np.array([[i, 0.1, 0.2, 0.3, 0.9, 4.0 + i, 900] for i in range(n)], np.float32)
    meta = {"generator": "experiments.detector.dataset", "version": 1, "split": split, "seeds": list(seeds),
            "images_per_seed": images_per_seed, "renderers": ["egl"], "rules": {"min_visible_pixels": 60},
            "counts": {"images": n, "boxes": n}}
    np.savez(path, images=images, boxes=boxes, seeds=np.repeat(np.array(seeds, np.int32), images_per_seed),
             meta=np.array(json.dumps(meta)))
    return images


def test_lossless_packing_reads_back_the_same_arrays(tmp_path):
    images = shard(tmp_path / "raw.npz", [3, 4])
    pack(tmp_path / "raw.npz", tmp_path / "packed.npz", quality=LOSSLESS)
    raw, packed = evaluate.load_split(tmp_path / "raw.npz"), evaluate.load_split(tmp_path / "packed.npz")
    assert np.array_equal(packed["images"], images)
    assert all(np.array_equal(a, b) for a, b in zip(raw["boxes"], packed["boxes"]))
    assert packed["meta"]["packed"] == {"format": "webp", "quality": LOSSLESS}
    assert packed["meta"]["seeds"] == [3, 4]


def test_lossy_packing_is_smaller_and_close(tmp_path):
    images = shard(tmp_path / "raw.npz", [0, 1, 2])
    pack(tmp_path / "raw.npz", tmp_path / "packed.npz", quality=90)
    got = evaluate.load_split(tmp_path / "packed.npz")["images"]
    assert (tmp_path / "packed.npz").stat().st_size < (tmp_path / "raw.npz").stat().st_size / 3
    err = np.abs(got.astype(int) - images.astype(int)).mean()
    assert 0 < err < 6  # lossy, yet within a few grey levels on average


def test_shards_are_joined_in_order_with_their_image_indices(tmp_path):
    a = shard(tmp_path / "a.npz", [0, 1], seed=1)
    b = shard(tmp_path / "b.npz", [2], seed=2)
    pack([tmp_path / "a.npz", tmp_path / "b.npz"], tmp_path / "train.npz", quality=LOSSLESS)
    got = evaluate.load_split(tmp_path / "train.npz")
    assert np.array_equal(got["images"], np.concatenate([a, b]))
    assert [float(bx[0, 4]) for bx in got["boxes"]] == [4.0, 5.0, 6.0, 7.0, 4.0, 5.0]  # each image kept its box
    assert got["meta"]["seeds"] == [0, 1, 2]
    assert got["meta"]["counts"] == {"images": 6, "boxes": 6}


def test_shards_that_do_not_belong_together_are_refused(tmp_path):
    shard(tmp_path / "a.npz", [0, 1])
    shard(tmp_path / "b.npz", [1, 2])
    shard(tmp_path / "v.npz", [9], split="val")
    with pytest.raises(ValueError, match="share scene seeds"):
        pack([tmp_path / "a.npz", tmp_path / "b.npz"], tmp_path / "x.npz")
    with pytest.raises(ValueError, match="'split' differs"):
        pack([tmp_path / "a.npz", tmp_path / "v.npz"], tmp_path / "x.npz")
    pack(tmp_path / "a.npz", tmp_path / "p.npz")
    with pytest.raises(ValueError, match="already packed"):
        pack(tmp_path / "p.npz", tmp_path / "x.npz")
    with pytest.raises(ValueError, match="quality"):
        pack(tmp_path / "a.npz", tmp_path / "x.npz", quality=0)
    assert not (tmp_path / "x.npz").exists()


def test_damaged_image_bytes_are_named(tmp_path):
    shard(tmp_path / "a.npz", [0])
    pack(tmp_path / "a.npz", tmp_path / "p.npz")
    with np.load(tmp_path / "p.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["webp"][arrays["offsets"][1]:arrays["offsets"][1] + 40] = 0  # image 1's header
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match=r"bad.npz, image 1: not a readable WebP image"):
        evaluate.load_split(tmp_path / "bad.npz")


def test_cli_packs_and_reports_a_missing_file_in_one_line(tmp_path, capsys):
    shard(tmp_path / "a.npz", [0])
    assert main(["pack-detector-data", str(tmp_path / "a.npz"), "--out", str(tmp_path / "p.npz")]) == 0
    assert "MiB" in capsys.readouterr().out
    assert main(["pack-detector-data", str(tmp_path / "nope.npz"), "--out", str(tmp_path / "q.npz")]) != 0
    err = capsys.readouterr().err
    assert "nope.npz: no such dataset file" in err and "Traceback" not in err

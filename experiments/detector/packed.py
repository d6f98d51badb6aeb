"""Dataset files with their images stored as WebP: some 60 times smaller than the generator's.

A split of 12,000 images at the network size is 3.2 GB as the generator writes it
(`experiments.detector.dataset.generate`), too much to copy to a training machine on a slow or
capped link. A packed file holds the same boxes, seeds and meta, and the images encoded one by
one as WebP: at quality 90 about 4.6 kB an image, a mean error of one grey level in 255; at 101,
lossless, about 19 kB. `evaluate.load_split` (and so training and evaluation) reads either kind.

Arrays of a packed file: webp (total bytes,) uint8, the encoded images one after another;
offsets (N + 1,) int64, where each image's bytes start and end; boxes, seeds as in the
generator's file; meta, its JSON with "packed": {"format": "webp", "quality": Q} added.
"""
from __future__ import annotations

import json
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

LOSSLESS = 101  # OpenCV's WebP quality above 100 means lossless


def _encode(img: np.ndarray, quality: int) -> np.ndarray:
    ok, buf = cv2.imencode(".webp", np.ascontiguousarray(img[:, :, ::-1]), [cv2.IMWRITE_WEBP_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not encode an image as WebP")
    return buf.reshape(-1)


def _decode(buf: np.ndarray, where: str) -> np.ndarray:
    img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"{where}: not a readable WebP image")
    return np.ascontiguousarray(img[:, :, ::-1])


# Meta keys that shards of one split must share; seeds, counts and renderers are combined.
SHARED_META = ("generator", "version", "split", "images_per_seed", "render_size", "image_size", "rules", "scenes")


def _read_shard(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    with np.load(path) as z:
        if "webp" in z:
            raise ValueError(f"{path}: already packed")
        missing = [k for k in ("images", "boxes", "seeds") if k not in z]
        if missing:
            raise ValueError(f"{path}: not a dataset file (no {', '.join(missing)})")
        meta = json.loads(str(z["meta"])) if "meta" in z else {}
        return z["images"], z["boxes"], z["seeds"], meta


def _combine(metas: list[dict], paths: list[Path]) -> dict:
    """One meta for shards of one split: the shared keys must agree, seeds must not repeat."""
    out = dict(metas[0])
    for m, p in zip(metas[1:], paths[1:]):
        for k in SHARED_META:
            if m.get(k) != out.get(k):
                raise ValueError(f"{p}: its meta {k!r} differs from {paths[0]}'s; shards must be of one split, "
                                 "rendered by one generator")
    seeds = [s for m in metas for s in m.get("seeds", [])]
    if len(set(seeds)) != len(seeds):
        raise ValueError("the shards share scene seeds: " + ", ".join(str(p) for p in paths))
    out["seeds"] = seeds
    out["renderers"] = sorted({r for m in metas for r in m.get("renderers", [])})
    counts = [m.get("counts", {}) for m in metas]
    out["counts"] = {k: sum(int(c.get(k, 0)) for c in counts) for k in counts[0]}
    return out


def pack(sources, dst, quality: int = 90, threads: int = 2) -> Path:
    """Write ``dst``: the generator's file(s) ``sources`` (one path, or shards of one split in
    order) with the images as WebP at ``quality`` (1-100 lossy, 101 lossless). Returns its path."""
    if isinstance(quality, bool) or not isinstance(quality, (int, np.integer)) or not 1 <= quality <= LOSSLESS:
        raise ValueError(f"quality: expected an integer from 1 to {LOSSLESS} (lossless), got {quality!r}")
    paths = [Path(sources)] if isinstance(sources, (str, Path)) else [Path(p) for p in sources]
    if not paths:
        raise ValueError("pack: no dataset files given")
    dst = Path(dst)
    bufs, boxes, seeds, metas = [], [], [], []
    with ThreadPoolExecutor(max(1, int(threads))) as pool:  # OpenCV releases the GIL while it codes
        for path in paths:
            images, b, sd, meta = _read_shard(path)
            b = np.array(b, np.float32).reshape(-1, 7)
            b[:, 0] += len(bufs)  # image indices continue across shards
            boxes.append(b)
            seeds.append(sd)
            metas.append(meta)
            bufs += list(pool.map(lambda im: _encode(im, quality), images))
            del images
    meta = _combine(metas, paths)
    offsets = np.zeros(len(bufs) + 1, np.int64)
    offsets[1:] = np.cumsum([len(b) for b in bufs])
    meta["packed"] = {"format": "webp", "quality": int(quality)}
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f".{dst.name}.partial")
    with open(tmp, "wb") as f:
        np.savez(f, webp=np.concatenate(bufs) if bufs else np.zeros(0, np.uint8), offsets=offsets,
                 boxes=np.concatenate(boxes), seeds=np.concatenate(seeds),
                 meta=np.array(json.dumps(meta, sort_keys=True)))
    os.replace(tmp, dst)
    return dst


def unpack_images(webp: np.ndarray, offsets: np.ndarray, where: str = "packed file",
                  threads: int | None = None) -> np.ndarray:
    """(N, H, W, 3) uint8 RGB images from a packed file's arrays."""
    n = len(offsets) - 1
    if n < 0 or (n and (offsets[0] != 0 or offsets[-1] != len(webp) or np.any(np.diff(offsets) <= 0))):
        raise ValueError(f"{where}: offsets do not index the WebP bytes")
    if n == 0:
        return np.zeros((0, 0, 0, 3), np.uint8)
    first = _decode(webp[offsets[0]:offsets[1]], f"{where}, image 0")
    out = np.empty((n,) + first.shape, np.uint8)
    out[0] = first

    def one(i: int) -> None:
        img = _decode(webp[offsets[i]:offsets[i + 1]], f"{where}, image {i}")
        if img.shape != first.shape:
            raise ValueError(f"{where}, image {i}: shape {img.shape}, the first image's is {first.shape}")
        out[i] = img

    with ThreadPoolExecutor(threads or min(16, os.cpu_count() or 1)) as pool:
        list(pool.map(one, range(1, n)))
    return out

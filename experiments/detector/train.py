"""Train the person detector (experiments.detector.net) on rendered data and export it to ONNX.

Targets (FastestDet's assignment, one documented change): with the decode
cx = (gx + tanh tx) / GRID_W, a cell can place a centre anywhere in (gx - 1, gx + 1), so the
cells that can reach a box centre at grid position (cx, cy) are floor(c) and floor(c) + 1 on each
axis: FastestDet assigns all four. We keep those whose needed offset |c - g| is at most
MAX_OFFSET on both axes (a tanh far in its tails learns slowly) and leave the others out of the
objectness loss (neither positive nor negative). The centre cell is always kept. Where two boxes
claim a cell, the larger box keeps it.

Losses: box regression by GIoU on the decoded boxes of the positive cells; objectness by binary
cross-entropy with an IoU-aware target on the positives (0.5 + 0.5 IoU of the cell's current
box, detached, so the score ranks well-placed boxes first, which NMS keeps) and 0 elsewhere,
both normalised by the number of positives. Total = objectness + REG_WEIGHT * regression.

Augmentation: `experiments.detector.augment`, a batch at a time on the training device.

AdamW, linear warm-up then cosine decay; an exponential moving average of the weights is what
is evaluated and exported. Everything follows from the seed (torch.manual_seed, one numpy
Generator for data order and augmentation, deterministic algorithms, a fixed thread count): on
the CPU the same arguments give bit-identical weights. On a CUDA device the training images stay
on the device and the batches are augmented there; the run is reproducible on that device and
software up to the few CUDA kernels without a deterministic version (torch warns of those).
"""
from __future__ import annotations

import json
import math
import platform
import time
from copy import deepcopy
from pathlib import Path

import numpy as np

from dodt.config import LearnedConfig
from dodt.learned import layout
from dodt.learned.model import sha256_of
from experiments.detector import evaluate
from experiments.detector.augment import apply as augment_images, draw, move_boxes

MODEL_NAME = "person_detector"
MAX_OFFSET = 0.85  # grid cells: the largest centre offset a positive cell must reach
REG_WEIGHT = 2.0
IOU_TARGET_FLOOR = 0.5  # objectness target of a positive = floor + (1 - floor) * IoU
NMS_IOU = evaluate.NMS_IOU
OPSET = 17
MAX_ONNX_BYTES = 2 * 1024 * 1024


# --------------------------------------------------------------------------- data


def load_data(path) -> dict:
    """images (N, H, W, 3) uint8 at the network size; per-image boxes (K, 6)."""
    data = evaluate.load_split(path)
    if data["images"].shape[1:] != (layout.INPUT_H, layout.INPUT_W, 3):
        raise ValueError(f"{path}: images must be (N, {layout.INPUT_H}, {layout.INPUT_W}, 3), "
                         f"got {data['images'].shape}")
    return data


def build_targets(boxes_per_image: list[np.ndarray], ignored_per_image: list[np.ndarray],
                  grid: tuple[int, int] = (layout.GRID_H, layout.GRID_W)):
    """Per-cell targets on a ``grid`` (GH, GW) (the head's; stride 16 by default): box
    (B, GH, GW, 4) as (x1, y1, x2, y2) fractions, positive mask and ignore mask (B, GH, GW)."""
    GH, GW = grid
    B = len(boxes_per_image)
    tbox = np.zeros((B, GH, GW, 4), np.float32)
    pos = np.zeros((B, GH, GW), bool)
    ign = np.zeros((B, GH, GW), bool)

    def cells(box):
        cx, cy = (box[0] + box[2]) / 2 * GW, (box[1] + box[3]) / 2 * GH
        ix, iy = min(int(cx), GW - 1), min(int(cy), GH - 1)
        out = []
        for gx in (ix, ix + 1):
            for gy in (iy, iy + 1):
                if gx >= GW or gy >= GH:
                    continue
                reach = abs(cx - gx) <= MAX_OFFSET and abs(cy - gy) <= MAX_OFFSET
                out.append((gx, gy, reach or (gx == ix and gy == iy)))
        return out

    for b, (boxes, ignored) in enumerate(zip(boxes_per_image, ignored_per_image)):
        for box in ignored:
            for gx, gy, _ in cells(box):
                ign[b, gy, gx] = True
        if len(boxes):
            area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
            for k in np.argsort(area, kind="stable"):  # the larger box is written last and keeps the cell
                for gx, gy, positive in cells(boxes[k]):
                    if positive:
                        pos[b, gy, gx] = True
                        tbox[b, gy, gx] = boxes[k]
                    else:
                        ign[b, gy, gx] = True
    ign &= ~pos
    return tbox, pos, ign


# --------------------------------------------------------------------------- model side


def _torch():
    import torch

    return torch


def decode_torch(reg, gx, gy, grid: tuple[int, int] = (layout.GRID_H, layout.GRID_W)):
    """(P, 4) raw (tx, ty, tw, th) at cells (gx, gy) of a ``grid`` (GH, GW) -> (P, 4) boxes
    (x1, y1, x2, y2), fractions."""
    torch = _torch()
    cx = (gx + torch.tanh(reg[:, 0])) / grid[1]
    cy = (gy + torch.tanh(reg[:, 1])) / grid[0]
    w = torch.sigmoid(reg[:, 2])
    h = torch.sigmoid(reg[:, 3])
    return torch.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], dim=1)


def giou(a, b):
    """IoU and generalised IoU of matching rows of (P, 4) boxes."""
    torch = _torch()
    x1 = torch.maximum(a[:, 0], b[:, 0])
    y1 = torch.maximum(a[:, 1], b[:, 1])
    x2 = torch.minimum(a[:, 2], b[:, 2])
    y2 = torch.minimum(a[:, 3], b[:, 3])
    inter = (x2 - x1).clamp(min=0) * (y2 - y1).clamp(min=0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a + area_b - inter + 1e-9
    iou = inter / union
    ex1 = torch.minimum(a[:, 0], b[:, 0])
    ey1 = torch.minimum(a[:, 1], b[:, 1])
    ex2 = torch.maximum(a[:, 2], b[:, 2])
    ey2 = torch.maximum(a[:, 3], b[:, 3])
    enclose = (ex2 - ex1) * (ey2 - ey1) + 1e-9
    return iou, iou - (enclose - union) / enclose


def detection_loss(out, tbox, pos, ign):
    """(total, objectness, regression) for a batch of raw outputs (B, 5, GH, GW)."""
    torch = _torch()
    F = torch.nn.functional
    obj = out[:, 0]
    b, gy, gx = torch.nonzero(pos, as_tuple=True)
    n_pos = max(int(b.numel()), 1)
    target = torch.zeros_like(obj)
    if b.numel():
        reg = out[b, 1:, gy, gx]
        pred = decode_torch(reg, gx.to(out.dtype), gy.to(out.dtype), tuple(out.shape[2:]))
        iou, g = giou(pred, tbox[b, gy, gx])
        reg_loss = (1.0 - g).sum() / n_pos
        target[b, gy, gx] = IOU_TARGET_FLOOR + (1 - IOU_TARGET_FLOOR) * iou.detach().clamp(0, 1)
    else:
        reg_loss = out.sum() * 0.0
    weight = (~ign).to(out.dtype)
    obj_loss = (F.binary_cross_entropy_with_logits(obj, target, reduction="none") * weight).sum() / n_pos
    return obj_loss + REG_WEIGHT * reg_loss, obj_loss, reg_loss


class EMA:
    """Exponential moving average of a model's parameters and buffers."""

    def __init__(self, model, decay: float = 0.998, ramp: float = 1000.0):
        self.model = deepcopy(model).eval()
        for p in self.model.parameters():
            p.requires_grad_(False)
        self.decay, self.ramp, self.updates = decay, ramp, 0

    def update(self, model) -> None:
        torch = _torch()
        self.updates += 1
        d = self.decay * (1 - math.exp(-self.updates / self.ramp))
        with torch.no_grad():
            src = model.state_dict()
            mine = self.model.state_dict()
            floats = [k for k, v in mine.items() if v.dtype.is_floating_point]
            # one fused lerp over all float tensors: v += (1 - d) (src - v)
            torch._foreach_lerp_([mine[k] for k in floats], [src[k].detach() for k in floats], 1.0 - d)
            for k, v in mine.items():
                if not v.dtype.is_floating_point:
                    v.copy_(src[k])


def predict(model, images: np.ndarray, batch: int = 32) -> np.ndarray:
    """Raw outputs of a torch model (on its own device) for uint8 images at the network size."""
    torch = _torch()
    model.eval()
    dev = next(model.parameters()).device
    outs = []
    with torch.no_grad():
        for i in range(0, len(images), batch):
            x = torch.from_numpy(layout.to_tensor(images[i:i + batch])).to(dev)
            outs.append(model(x.contiguous(memory_format=torch.channels_last)).float().cpu().numpy())
    return np.concatenate(outs) if outs else np.zeros((0, *layout.output_shape(model.stride)[1:]), np.float32)


def validate(model, data: dict, max_distance: float = 10.0) -> dict:
    dets = evaluate.decode_all(predict(model, data["images"]), 0.05)
    return evaluate.evaluate_detections(dets, data["boxes"], max_distance, 0.5)


def export_onnx(model, path: Path) -> None:
    """Fixed-shape ONNX (opset 17): input "images" (1, 3, H, W), output "preds" (1, 5, GH, GW), the
    grid of the model's head stride."""
    torch = _torch()
    m = deepcopy(model).cpu().eval().to(memory_format=torch.contiguous_format)
    x = torch.zeros(1, 3, layout.INPUT_H, layout.INPUT_W)
    path.parent.mkdir(parents=True, exist_ok=True)
    kwargs = dict(input_names=["images"], output_names=["preds"], opset_version=OPSET, do_constant_folding=True)
    try:
        torch.onnx.export(m, (x,), str(path), dynamo=False, **kwargs)
    except TypeError:  # an exporter without the dynamo switch
        torch.onnx.export(m, (x,), str(path), **kwargs)


def check_onnx(model, path: Path, images: np.ndarray) -> float:
    """Largest |onnxruntime - torch on the CPU| over the given images (the size limit is checked too)."""
    torch = _torch()
    size = path.stat().st_size
    if size > MAX_ONNX_BYTES:
        raise RuntimeError(f"{path}: {size} bytes, over the {MAX_ONNX_BYTES} limit")
    sess = evaluate.onnx_session(path, threads=torch.get_num_threads())
    ref = predict(deepcopy(model).cpu(), images)
    got = evaluate.run_onnx(sess, images)
    return float(np.max(np.abs(ref - got))) if len(images) else 0.0


def lr_at(step: int, total: int, base: float, warmup: int) -> float:
    if step < warmup:
        return base * (step + 1) / warmup
    t = (step - warmup) / max(total - warmup, 1)
    return base * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(t, 1.0))))


# --------------------------------------------------------------------------- training


def _meta_summary(meta: dict) -> dict:
    keys = ("generator", "version", "split", "seeds", "images_per_seed", "counts", "renderers", "rules", "packed")
    return {k: meta[k] for k in keys if k in meta}


def option_flags(device: str, arch: str, batch_size: int, lr: float, warmup_epochs: float) -> str:
    """The train-detector flags for the options that differ from train()'s defaults, for the
    command written into a model's record."""
    flags = ""
    for flag, value, default in (("--device", device, "cpu"), ("--arch", arch, "base"),
                                 ("--batch-size", batch_size, 32), ("--lr", lr, 3e-3),
                                 ("--warmup-epochs", warmup_epochs, 1.0)):
        if value != default:
            flags += f" {flag} {value}"
    return flags


def train(data_dir, out_dir, epochs: int, seed: int, batch_size: int = 32, threads: int = 2,
          progress=print, lr: float = 3e-3, weight_decay: float = 5e-4, eval_every: int = 5,
          warmup_epochs: float = 1.0, command: str | None = None, device: str = "cpu",
          arch: str = "base") -> dict:
    """Train on ``data_dir``/train.npz, validate on ``data_dir``/val.npz, and write to ``out_dir``:
    person_detector.onnx, person_detector.json (what the run was and its validation figures, also
    returned), person_detector.pt (the averaged weights) and train_log.jsonl (one row per epoch).

    ``device`` is "cpu" or a torch CUDA device ("cuda", "cuda:1"); ``arch`` a size from
    `experiments.detector.net.ARCHS`. ``progress`` receives one line per epoch (JSON). On the
    CPU the same arguments and thread count give bit-identical weights. torch's global settings
    (threads, deterministic algorithms, flushing denormals) are set for the run and put back
    afterwards.
    """
    torch = _torch()
    from experiments.detector.net import ARCHS

    if arch not in ARCHS:
        raise ValueError(f"arch: unknown {arch!r}; expected one of {', '.join(ARCHS)}")
    if str(device) != "cpu":
        if not str(device).startswith("cuda"):
            raise ValueError(f"device: expected 'cpu' or a CUDA device such as 'cuda', got {device!r}")
        if not torch.cuda.is_available():
            raise ValueError(f"device {device!r}: this torch ({torch.__version__}) sees no CUDA device")
    saved = (torch.get_num_threads(), torch.are_deterministic_algorithms_enabled())
    try:
        return _train(data_dir, out_dir, epochs, seed, batch_size, threads, progress, lr, weight_decay,
                      eval_every, warmup_epochs, command, torch.device(device), arch)
    finally:
        torch.set_num_threads(saved[0])
        torch.use_deterministic_algorithms(saved[1])
        torch.set_flush_denormal(False)


def _batch(train_images, train_boxes, idx: np.ndarray, rng: np.random.Generator, grid: tuple[int, int]):
    """One augmented batch: images (B, 3, H, W) on the images' device and the targets on a ``grid``
    (GH, GW) as tensors on that device."""
    torch = _torch()
    dev = train_images.device
    d = draw(rng, len(idx))
    bs, igs = [], []
    for j, i in enumerate(idx):
        b, ig = move_boxes(train_boxes[i][:, :4], d, j, layout.INPUT_H, layout.INPUT_W)
        bs.append(b)
        igs.append(ig)
    x = augment_images(train_images[torch.as_tensor(idx, device=dev)], d)
    tbox, pos, ign = build_targets(bs, igs, grid)
    return x, torch.from_numpy(tbox).to(dev), torch.from_numpy(pos).to(dev), torch.from_numpy(ign).to(dev)


def _train(data_dir, out_dir, epochs, seed, batch_size, threads, progress, lr, weight_decay, eval_every,
           warmup_epochs, command, device, arch) -> dict:
    torch = _torch()
    from experiments.detector.net import build_model, count_parameters, describe

    data_dir, out_dir = Path(data_dir), Path(out_dir)
    for split in ("train", "val"):
        if not (data_dir / f"{split}.npz").is_file():
            raise FileNotFoundError(f"{data_dir / (split + '.npz')}: no such dataset file")
    if int(epochs) < 1:
        raise ValueError(f"epochs: must be >= 1, got {epochs}")
    t_start = time.time()
    torch.set_num_threads(int(threads))
    torch.set_flush_denormal(True)  # denormal floats slowed CPU training some 50-fold
    torch.manual_seed(int(seed))
    on_gpu = device.type == "cuda"
    # CUDA has no deterministic version of a few kernels: warn about those rather than stop.
    torch.use_deterministic_algorithms(True, warn_only=on_gpu)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xD7]))

    _mkdir(out_dir)
    (out_dir / "train_log.jsonl").write_text("")
    train_data = load_data(data_dir / "train.npz")
    val_data = load_data(data_dir / "val.npz")
    n = len(train_data["images"])
    progress(f"train: {n} images, {sum(len(b) for b in train_data['boxes'])} boxes; "
             f"val: {len(val_data['images'])} images; device {device}, arch {arch}, threads {threads}, "
             f"batch {batch_size}")
    train_images = torch.from_numpy(train_data["images"]).to(device)  # uint8, augmented a batch at a time

    model = build_model(arch).to(device).to(memory_format=torch.channels_last)
    n_params = count_parameters(model)
    grid = tuple(layout.output_shape(model.stride)[2:])
    decay, no_decay = [], []
    for name, p in model.named_parameters():
        (no_decay if p.ndim <= 1 else decay).append(p)
    opt = torch.optim.AdamW([{"params": decay, "weight_decay": weight_decay},
                             {"params": no_decay, "weight_decay": 0.0}], lr=lr, betas=(0.9, 0.99))
    ema = EMA(model)
    steps_per_epoch = max(n // batch_size, 1)  # the last partial batch is dropped (BatchNorm)
    total_steps = steps_per_epoch * int(epochs)
    warmup = max(int(warmup_epochs * steps_per_epoch), 1)
    curve = []
    step = 0
    images_seen = 0
    train_time = 0.0
    for epoch in range(1, int(epochs) + 1):
        model.train()
        t0 = time.time()
        order = rng.permutation(n)
        sums = torch.zeros(3, device=device)  # summed on the device: no wait for it every step
        for k in range(steps_per_epoch):
            idx = order[k * batch_size:(k + 1) * batch_size]
            x, tbox, pos, ign = _batch(train_images, train_data["boxes"], idx, rng, grid)
            for g in opt.param_groups:
                g["lr"] = lr_at(step, total_steps, lr, warmup)
            out = model(x)
            loss, lo, lr_ = detection_loss(out, tbox, pos, ign)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
            opt.step()
            ema.update(model)
            sums += torch.stack([loss.detach(), lo.detach(), lr_.detach()])
            step += 1
            images_seen += len(idx)
        sums = sums.cpu().numpy().astype(np.float64)
        dt = time.time() - t0
        train_time += dt
        row = {"epoch": epoch, "loss": sums[0] / steps_per_epoch, "obj_loss": sums[1] / steps_per_epoch,
               "reg_loss": sums[2] / steps_per_epoch, "lr": lr_at(step - 1, total_steps, lr, warmup),
               "images_per_s": steps_per_epoch * batch_size / dt}
        if eval_every and (epoch % eval_every == 0 or epoch == int(epochs)):
            v = validate(ema.model, val_data)
            row.update({"val_ap50": v["ap50"], "val_best_f1_threshold": v["best_f1_threshold"],
                        "val_precision": v["precision"], "val_recall": v["recall"]})
            torch.save(ema.model.state_dict(), out_dir / f"{MODEL_NAME}_last.pt")  # in case a run is cut short
        curve.append(row)
        progress(json.dumps({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()}))
        with open(_mkdir(out_dir) / "train_log.jsonl", "a") as f:
            f.write(json.dumps(row) + "\n")

    # Export the averaged weights and check them.
    out_dir.mkdir(parents=True, exist_ok=True)
    final = ema.model
    torch.save(final.state_dict(), out_dir / f"{MODEL_NAME}.pt")
    onnx_path = out_dir / f"{MODEL_NAME}.onnx"
    export_onnx(final, onnx_path)
    max_diff = check_onnx(final, onnx_path, val_data["images"][:8])
    if not max_diff < 1e-3:
        raise RuntimeError(f"{onnx_path}: onnxruntime and torch disagree by {max_diff}")
    # The operating point: the best-F1 threshold on validation, then the figures through onnxruntime.
    v_torch = validate(final, val_data)
    threshold = v_torch["best_f1_threshold"]
    # through the run time's suppression (soft-NMS, LearnedConfig.soft_nms_sigma)
    soft = LearnedConfig().soft_nms_sigma
    figures = evaluate.average_precision(onnx_path, data_dir / "val.npz", operating_threshold=threshold,
                                         threads=threads, soft_sigma=soft)
    figures_15 = evaluate.average_precision(onnx_path, data_dir / "val.npz", max_distance=15.0,
                                            operating_threshold=threshold, threads=threads, soft_sigma=soft)
    if command is None:
        command = f"dodt-nav train-detector --data {data_dir} --epochs {int(epochs)} --seed {int(seed)}"
        if threads != 2:
            command += f" --threads {threads}"
        command += option_flags(str(device), arch, batch_size, lr, warmup_epochs)
    info = {
        "model": f"{MODEL_NAME}.onnx",
        "sha256": sha256_of(onnx_path),
        "onnx_bytes": onnx_path.stat().st_size,
        "opset": OPSET,
        "parameters": n_params,
        "architecture": describe(arch),
        "arch": arch,
        "input": {"name": "images", "shape": [1, 3, layout.INPUT_H, layout.INPUT_W],
                  "format": "RGB float32 in [0, 1], resize_for_network then to_tensor"},
        "output": {"name": "preds", "shape": list(layout.output_shape(final.stride)),
                   "decode": "dodt.learned.layout.decode"},
        "score_threshold": threshold,
        "nms_iou": NMS_IOU,
        "soft_nms_sigma": soft,
        "command": command,
        "seed": int(seed),
        "epochs": int(epochs),
        "batch_size": int(batch_size),
        "threads": int(threads),
        "device": torch.cuda.get_device_name(device) if on_gpu else "cpu",
        "lr": lr,
        "weight_decay": weight_decay,
        "train_data": _meta_summary(train_data["meta"]),
        "val_data": _meta_summary(val_data["meta"]),
        "train_images": n,
        "train_wall_time_s": round(time.time() - t_start, 1),
        "train_loop_time_s": round(train_time, 1),
        "images_per_s": round(images_seen / max(train_time, 1e-9), 2),
        "onnx_max_abs_diff": max_diff,
        "validation": figures,
        "validation_15m": {k: figures_15[k] for k in ("ap50", "precision", "recall", "boxes")},
        "curve": curve,
        "torch": torch.__version__,
        "python": platform.python_version(),
    }
    (out_dir / f"{MODEL_NAME}.json").write_text(json.dumps(info, indent=1) + "\n")
    progress(f"validation AP@0.5 (<= 10 m) {figures['ap50']:.4f} at threshold {threshold}: precision "
             f"{figures['precision']}, recall {figures['recall']}; wrote {onnx_path} ({info['onnx_bytes']} bytes)")
    return info


def _mkdir(p: Path) -> Path:
    p.mkdir(parents=True, exist_ok=True)
    return p


if __name__ == "__main__":  # python -m experiments.detector.train DATA OUT EPOCHS SEED [BATCH THREADS]
    import sys

    a = sys.argv[1:]
    train(a[0], a[1], int(a[2]), int(a[3]), batch_size=int(a[4]) if len(a) > 4 else 32,
          threads=int(a[5]) if len(a) > 5 else 2)

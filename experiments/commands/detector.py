"""The learned person detector: `train-detector`, `eval-detector` and `pack-detector-data` (rendering its
dataset, training it with PyTorch, scoring it through onnxruntime, packing the dataset for transfer)."""
from __future__ import annotations

import json
from pathlib import Path

from dodt.config import LearnedConfig

from experiments.commands.common import UserError, add_command, examples, real, seed, whole


def add_parser(sub) -> None:
    t = add_command(
        sub, "train-detector",
        help="render the person dataset (where missing) and train the learned detector (PyTorch)",
        description="Train the optional learned person detector (YOLO-MAD, used by the dodt+yolo preset). The "
                    "training and validation splits are rendered by the simulator into --data where missing "
                    "(their scene seeds never shared), the network is trained with PyTorch, validated every "
                    "--eval-every epochs, and exported to OUT/person_detector.onnx, with person_detector.json "
                    "recording the command that made it and its validation figures. Needs the train extra: "
                    "pip install -e '.[train]'. The result depends on --seed and --threads.",
        epilog=examples("dodt-nav train-detector --epochs 5 --train-seeds 0:20 --val-seeds 1000:1005 "
                        "--out runs/detector_small",
                        "dodt-nav train-detector --device cuda --arch wide --threads 8 --out runs/detector_wide"),
        func=cmd_train_detector)
    _data_options(t)
    t.add_argument("--epochs", type=whole(1, 100_000), default=60)
    t.add_argument("--seed", type=seed, default=0, help="training seed (weights, data order, augmentation)")
    t.add_argument("--threads", type=whole(1, 1024), default=2, help="PyTorch threads (the result depends on it)")
    t.add_argument("--device", default="cpu", help="cpu, or a CUDA device (cuda, cuda:1)")
    t.add_argument("--arch", default="base", help="network size: base (FastestDet's shape), wide, or wide8 (wide with a stride-8 head)")
    t.add_argument("--batch-size", type=whole(2, 100_000, "a whole number (BatchNorm needs 2)"), default=32)
    t.add_argument("--lr", type=real(0.0, 10.0, lo_open=True), default=3e-3, help="AdamW's peak learning rate")
    t.add_argument("--warmup-epochs", type=real(0.0, 100_000.0), default=1.0, help="linear warm-up before the cosine decay")
    t.add_argument("--eval-every", type=whole(0), default=5, help="validate every N epochs (0: at the end only)")
    t.add_argument("--out", default="runs/detector", help="folder for person_detector.onnx and .json")

    e = add_command(
        sub, "eval-detector", help="validation AP@0.5 of a person detector model through onnxruntime",
        description="Score a person detector model (the shipped one, or --model) on the validation split, run "
                    "through onnxruntime as at run time: average precision at IoU 0.5 over the people within "
                    "--max-distance, and recall by distance, with the suppression (--soft-nms, --nms-iou) and "
                    "fused views (--views) given. The validation split is rendered into --data where missing; no "
                    "training images are needed.",
        epilog=examples("dodt-nav eval-detector",
                        "dodt-nav eval-detector --model runs/detector/person_detector.onnx --views full,flip",
                        "dodt-nav eval-detector --score-floor 0.001 --min-visible-px 400"),
        func=cmd_eval_detector)
    _data_options(e)
    e.add_argument("--model", default=None, help="an ONNX model with its .json (default: the shipped one)")
    e.add_argument("--max-distance", type=real(0.0, 1000.0, lo_open=True), default=10.0, help="people within this distance count")
    e.add_argument("--nms-iou", type=real(0.0, 1.0, lo_open=True), default=0.45, help="non-maximum suppression IoU (FastestDet's 0.45)")
    e.add_argument("--score-floor", type=real(0.0, 1.0, lo_open=True, hi_open=True), default=0.05,
                   help="detections scoring less are left out of the AP (default %(default)s; "
                        "YOLO evaluations use 0.001, which counts more of the curve's tail)")
    e.add_argument("--soft-nms", type=real(0.0, 100.0), default=LearnedConfig().soft_nms_sigma, metavar="SIGMA",
                   help="Gaussian soft-NMS with this sigma, as at run time (default %(default)s); "
                        "0: NMS at --nms-iou")
    e.add_argument("--min-visible-px", type=whole(0), default=0,
                   help="ignore people showing fewer pixels at 640x480 (the perception metrics use 400)")
    e.add_argument("--views", default="full",
                   help="views fused at run time, a comma list of full, flip, center, center-flip")

    pk = add_command(
        sub, "pack-detector-data", help="a person dataset file (or shards of one split) with its "
                                        "images as WebP, some 60 times smaller, for copying to a training machine",
        description="Pack a rendered person dataset file (or the shards of one split) into one file whose images "
                    "are stored as WebP: some 60 times smaller at quality 90, for copying to a training machine "
                    "over a slow link. Training and evaluation read packed and unpacked files alike.",
        epilog=examples("dodt-nav pack-detector-data runs/detector_data/train.npz --out train_packed.npz",
                        "dodt-nav pack-detector-data shard0/train.npz shard1/train.npz --out train.npz --quality 101"),
        func=cmd_pack_detector_data)
    pk.add_argument("files", nargs="+", help="train.npz / val.npz files of one split, as rendered")
    pk.add_argument("--out", required=True, help="the packed file to write")
    pk.add_argument("--quality", type=whole(1, 101), default=90, help="WebP quality 1-100, or 101 for lossless")


def _data_options(d) -> None:
    """The dataset's folder, splits and size: shared by train-detector and eval-detector."""
    d.add_argument("--data", default="runs/detector_data", help="dataset folder (train.npz, val.npz)")
    d.add_argument("--train-seeds", default="0:200", help="scene seeds of the training split")
    d.add_argument("--val-seeds", default="1000:1040", help="scene seeds of the validation split")
    d.add_argument("--images-per-seed", type=whole(1, 100_000), default=20, help="images rendered per scene")


def detector_data(args, splits: tuple[str, ...] = ("train", "val")) -> Path:
    """The dataset folder, its ``splits`` generated where missing (seeds never shared)."""
    import numpy as np

    from experiments.detector import dataset
    from experiments.sweep import SweepError, parse_seeds

    try:
        train_seeds, val_seeds = parse_seeds(args.train_seeds), parse_seeds(args.val_seeds)
        dataset.check_disjoint(train_seeds, val_seeds)
    except (SweepError, ValueError) as e:
        raise UserError(str(e).replace("--seeds", "--train-seeds/--val-seeds")) from None
    data = Path(args.data)
    for split, seeds in (("train", train_seeds), ("val", val_seeds)):
        if split not in splits:
            continue
        if (data / f"{split}.npz").is_file():
            with np.load(data / f"{split}.npz") as z:
                meta = json.loads(str(z["meta"])) if "meta" in z else {}
            if meta.get("seeds") != list(seeds) or meta.get("images_per_seed") != args.images_per_seed:
                raise UserError(f"{data / (split + '.npz')} was rendered from other seeds or images per seed than "
                                f"asked; use another --data folder or the same options")
        else:
            print(f"rendering the {split} split: {len(seeds)} seeds x {args.images_per_seed} images into {data}",
                  flush=True)
            dataset.generate(data, split, seeds, args.images_per_seed)
    return data


def cmd_train_detector(args) -> int:
    try:
        import torch  # noqa: F401  (training only; run time uses onnxruntime)
    except ImportError:
        raise UserError("training needs PyTorch: pip install torch==2.13.0 onnx (or pip install -e '.[train]')") from None
    from experiments.detector.train import option_flags, train

    data = detector_data(args)
    command = (f"dodt-nav train-detector --data {args.data} --train-seeds {args.train_seeds} --val-seeds "
               f"{args.val_seeds} --images-per-seed {args.images_per_seed} --epochs {args.epochs} --seed {args.seed} "
               f"--threads {args.threads}")
    command += option_flags(args.device, args.arch, args.batch_size, args.lr, args.warmup_epochs)
    try:
        record = train(data, Path(args.out), epochs=args.epochs, seed=args.seed, threads=args.threads,
                       command=command, device=args.device, arch=args.arch, batch_size=args.batch_size,
                       lr=args.lr, eval_every=args.eval_every, warmup_epochs=args.warmup_epochs)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"wrote {args.out}/person_detector.onnx and person_detector.json; validation: "
          + json.dumps(record.get("validation", {}))[:400])
    return 0


def cmd_pack_detector_data(args) -> int:
    from experiments.detector.packed import pack

    missing = [f for f in args.files if not Path(f).is_file()]
    if missing:
        raise UserError(f"{missing[0]}: no such dataset file")
    try:
        out = pack(args.files, args.out, quality=args.quality)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"wrote {out} ({out.stat().st_size / 2**20:.1f} MiB)")
    return 0


def cmd_eval_detector(args) -> int:
    from dodt.learned.model import SHIPPED_MODEL, load_record
    from dodt.learned.views import parse_views
    from experiments.detector.evaluate import average_precision

    model = Path(args.model) if args.model else SHIPPED_MODEL
    load_record(model)  # a missing or corrupt model stops here with its name
    try:
        views = parse_views(args.views)
    except ValueError as e:
        raise UserError(f"--views: {e}") from None
    data = detector_data(args, splits=("val",))  # evaluation needs no training images
    r = average_precision(model, data / "val.npz", max_distance=args.max_distance, nms_iou=args.nms_iou,
                          min_visible_px=args.min_visible_px, views=views, soft_sigma=args.soft_nms,
                          score_threshold=args.score_floor)
    keys = ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()
                     if not isinstance(v, dict))
    print(f"{model.name} on {data / 'val.npz'}: {keys}")
    for k, v in r.items():
        if isinstance(v, dict):
            print(f"  {k}: " + ", ".join(f"{b} {x:.3f}" if isinstance(x, float) else f"{b} {x}" for b, x in v.items()))
    return 0

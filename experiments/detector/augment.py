"""Training augmentation for the person detector, a whole batch at a time, on the training device.

Our renderer has little lighting variety, so each image gets, independently:
- with probability 0.6 a random scale (0.7-1.4) about the centre and a shift of up to 20 % of
  the image, the uncovered border filled with the image's mean colour; boxes are clipped and
  kept when at least KEEP_FRACTION of their area stays in view (and they are at least 3 px tall
  and 2 px wide), the rest of those still partly in view are returned as ignored;
- with probability 0.5 a horizontal flip;
- photometric jitter: gain per channel and overall (0.8), contrast (0.6), saturation (0.5),
  gamma (0.5), Gaussian blur (0.25) and Gaussian noise (0.4).

Every random number is drawn from one numpy Generator, in a fixed order per batch (`draw`),
and the noise from a torch Generator seeded by it, so a seed fixes the batch on a given device
whatever the device. The geometry of the boxes is computed in numpy (`move_boxes`), the image
operations in torch (`apply`) on the device the images are on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

KEEP_FRACTION = 0.45  # of a box's area left in view after a crop, to keep it as a target
SCALE_RANGE = (0.7, 1.4)
MAX_SHIFT = 0.2  # fraction of the image
BLUR_RADIUS = 4  # px: the kernel's half width, 3 sigma of the largest blur (1.3 px)


@dataclass(frozen=True)
class Draw:
    """The random choices for a batch of B images (arrays of length B, or (B, 3) for gains)."""

    scale: np.ndarray
    shift: np.ndarray  # (B, 2) fractions of the width and height
    warped: np.ndarray  # bool
    flipped: np.ndarray  # bool
    gain: np.ndarray  # (B, 3)
    contrast: np.ndarray
    saturation: np.ndarray
    gamma: np.ndarray
    blur_sigma: np.ndarray  # 0: no blur
    noise_sigma: np.ndarray  # 0: no noise
    noise_seed: int


def draw(rng: np.random.Generator, n: int) -> Draw:
    """The choices for ``n`` images (probabilities and ranges as the module docstring says)."""
    def sometimes(p: float, values: np.ndarray, neutral: float) -> np.ndarray:
        on = rng.random(n) < p
        return np.where(on.reshape((n,) + (1,) * (values.ndim - 1)), values, neutral)

    warped = rng.random(n) < 0.6
    scale = np.where(warped, np.exp(rng.uniform(math.log(SCALE_RANGE[0]), math.log(SCALE_RANGE[1]), n)), 1.0)
    shift = np.where(warped[:, None], rng.uniform(-MAX_SHIFT, MAX_SHIFT, (n, 2)), 0.0)
    flipped = rng.random(n) < 0.5
    gain = sometimes(0.8, rng.uniform(0.85, 1.15, (n, 3)) * rng.uniform(0.6, 1.4, (n, 1)), 1.0)
    contrast = sometimes(0.6, rng.uniform(0.6, 1.4, n), 1.0)
    saturation = sometimes(0.5, rng.uniform(0.3, 1.6, n), 1.0)
    gamma = sometimes(0.5, np.exp(rng.uniform(math.log(0.6), math.log(1.6), n)), 1.0)
    blur = sometimes(0.25, rng.uniform(0.4, 1.3, n), 0.0)
    noise = sometimes(0.4, rng.uniform(0.005, 0.04, n), 0.0)
    return Draw(scale, shift, warped, flipped, gain, contrast, saturation, gamma, blur, noise,
                int(rng.integers(0, 2**62)))


def move_boxes(boxes: np.ndarray, d: Draw, i: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Image ``i``'s boxes (K, 4) fractions (x1, y1, x2, y2) after its scale, shift and flip:
    (kept (K', 4), ignored (J, 4))."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    ignored = np.zeros((0, 4))
    if d.warped[i] and len(b):
        s, (dx, dy) = d.scale[i], d.shift[i]
        b = b.copy()
        b[:, [0, 2]] = s * (b[:, [0, 2]] - 0.5) + 0.5 + dx
        b[:, [1, 3]] = s * (b[:, [1, 3]] - 0.5) + 0.5 + dy
        area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
        c = b.clip(0.0, 1.0)
        frac = (c[:, 2] - c[:, 0]).clip(0) * (c[:, 3] - c[:, 1]).clip(0) / np.maximum(area, 1e-12)
        big_enough = ((c[:, 3] - c[:, 1]) * height >= 3) & ((c[:, 2] - c[:, 0]) * width >= 2)
        keep = (frac >= KEEP_FRACTION) & big_enough
        ignored = c[(~keep) & (frac > 0)]
        b = c[keep]
    if d.flipped[i]:
        b = np.stack([1 - b[:, 2], b[:, 1], 1 - b[:, 0], b[:, 3]], axis=1).reshape(-1, 4)
        ignored = np.stack([1 - ignored[:, 2], ignored[:, 1], 1 - ignored[:, 0], ignored[:, 3]], axis=1).reshape(-1, 4)
    return b, ignored


def apply(images, d: Draw):
    """The augmented batch: (B, H, W, 3) uint8 torch tensor -> (B, 3, H, W) float32 in [0, 1] on
    the same device, in channels-last memory."""
    import torch
    import torch.nn.functional as F

    dev = images.device
    x = images.permute(0, 3, 1, 2).float().mul_(1.0 / 255.0)
    B = x.shape[0]

    def col(a, dims: int = 4):
        return torch.as_tensor(np.asarray(a, np.float32), device=dev).reshape((B,) + (-1,) + (1,) * (dims - 2))

    warped = np.flatnonzero(d.warped)
    if len(warped):
        # Output pixel u (normalised to [-1, 1]) shows input pixel (u - 2 shift) / scale.
        s = d.scale[warped]
        theta = np.zeros((len(warped), 2, 3), np.float32)
        theta[:, 0, 0] = theta[:, 1, 1] = 1.0 / s
        theta[:, :, 2] = -2.0 * d.shift[warped] / s[:, None]
        sub = x[torch.as_tensor(warped, device=dev)]
        mean = sub.mean(dim=(2, 3), keepdim=True)
        grid = F.affine_grid(torch.as_tensor(theta, device=dev), list(sub.shape), align_corners=False)
        sub = F.grid_sample(sub - mean, grid, mode="bilinear", padding_mode="zeros", align_corners=False) + mean
        x[torch.as_tensor(warped, device=dev)] = sub
    flipped = np.flatnonzero(d.flipped)
    if len(flipped):
        idx = torch.as_tensor(flipped, device=dev)
        x[idx] = x[idx].flip(-1)
    x = x * col(d.gain)
    m = x.mean(dim=(1, 2, 3), keepdim=True)
    x = (x - m) * col(d.contrast) + m
    gray = x.mean(dim=1, keepdim=True)
    x = gray + (x - gray) * col(d.saturation)
    x = x.clamp_(0.0, 1.0).pow_(col(d.gamma))
    blurred = np.flatnonzero(d.blur_sigma > 0)
    if len(blurred):
        idx = torch.as_tensor(blurred, device=dev)
        x[idx] = _gaussian_blur(x[idx], d.blur_sigma[blurred])
    if np.any(d.noise_sigma > 0):
        gen = torch.Generator(device=dev)
        gen.manual_seed(d.noise_seed)
        x = x + torch.randn(x.shape, generator=gen, device=dev) * col(d.noise_sigma)
    return x.clamp_(0.0, 1.0).contiguous(memory_format=torch.channels_last)


def _gaussian_blur(x, sigmas: np.ndarray):
    """Each image of (B, 3, H, W) blurred by its own sigma (px), separably, edges reflected."""
    import torch
    import torch.nn.functional as F

    B, C, H, W = x.shape
    t = np.arange(-BLUR_RADIUS, BLUR_RADIUS + 1, dtype=np.float64)
    k = np.exp(-0.5 * (t[None, :] / np.asarray(sigmas, np.float64)[:, None]) ** 2)
    k = np.repeat((k / k.sum(axis=1, keepdims=True)).astype(np.float32), C, axis=0)  # (B*C, 2R+1)
    k = torch.as_tensor(k, device=x.device)
    y = F.pad(x.reshape(1, B * C, H, W), (BLUR_RADIUS,) * 4, mode="reflect")
    y = F.conv2d(y, k[:, None, None, :], groups=B * C)
    y = F.conv2d(y, k[:, None, :, None], groups=B * C)
    return y.reshape(B, C, H, W)


def augment(img: np.ndarray, boxes: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One image augmented on the CPU: (H, W, 3) float32 in [0, 1], kept boxes (K, 4) and ignored
    boxes (J, 4) as fractions (x1, y1, x2, y2). For tests and looking at; training uses batches."""
    import torch

    d = draw(rng, 1)
    kept, ignored = move_boxes(boxes, d, 0, img.shape[0], img.shape[1])
    x = apply(torch.from_numpy(np.ascontiguousarray(img))[None], d)
    return x[0].permute(1, 2, 0).contiguous().numpy(), kept, ignored

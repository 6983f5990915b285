#!/usr/bin/env python3
"""Probe (not part of the build): would a texture cue find the hand where colour does not?

For a synthetic dataset with empty-scene images (camN/background*.png) and truth masks
(masks/camN/FRAME.png, 0 = background), compares each frame's local texture with the empty
scene's: the RMS of the grey gradient over a 7x7 window divided by the window's mean brightness
(so a gain or a shadow that scales the light leaves it alone). A pixel of the hand or the tool
whose colour is within 25 grey levels of the empty scene's ("hard": what a background model
without texture misses) is flagged when that ratio leaves [1/k, k]; the background's pixels
should not be.

    tools/texture_cue_probe.py DATASET FRAME[,FRAME...]

Needs numpy and pillow (a virtual environment: python3 -m venv /tmp/py && /tmp/py/bin/pip
install numpy pillow). Prints, for k = 1.3, 1.5 and 2, the share of hard foreground pixels and of
background pixels flagged, over every camera of the frames given.
"""

import os
import sys

import numpy as np
from PIL import Image


def box_mean(a, r):
    """Mean over a (2r+1)^2 window, edges repeated."""
    k = 2 * r + 1
    c = np.pad(np.pad(a, r, mode="edge").cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    return (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)


def texture(grey):
    """RMS central-difference gradient over 7x7 windows over the windows' mean brightness."""
    gx = np.zeros_like(grey)
    gy = np.zeros_like(grey)
    gx[:, 1:-1] = grey[:, 2:] - grey[:, :-2]
    gy[1:-1, :] = grey[2:, :] - grey[:-2, :]
    return np.sqrt(box_mean(gx * gx + gy * gy, 3)) / (box_mean(grey, 3) + 1.0)


def load(path):
    return np.asarray(Image.open(path).convert("RGB")).astype(np.float32)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    ds, frames = sys.argv[1], [int(f) for f in sys.argv[2].split(",")]
    cams = sorted(c for c in os.listdir(ds) if c.startswith("cam"))
    hard_ratios, bg_ratios = [], []
    for frame in frames:
        for cam in cams:
            image = load(f"{ds}/{cam}/{frame:06d}.png")
            empty = sorted(f for f in os.listdir(f"{ds}/{cam}") if f.startswith("background"))
            if not empty:
                sys.exit(f"{ds}/{cam}: no background*.png")
            background = load(f"{ds}/{cam}/{empty[0]}")
            mask = np.asarray(Image.open(f"{ds}/masks/{cam}/{frame:06d}.png"))
            foreground = (mask[..., 0] if mask.ndim == 3 else mask) > 0
            ratio = (texture(image.mean(2)) + 1e-3) / (texture(background.mean(2)) + 1e-3)
            hard = foreground & (np.abs(image - background).max(2) <= 25)
            hard_ratios.append(ratio[hard])
            bg_ratios.append(ratio[~foreground])
    hard, bg = np.concatenate(hard_ratios), np.concatenate(bg_ratios)
    print(f"{hard.size} hard foreground pixels, {bg.size} background pixels")
    for k in (1.3, 1.5, 2.0):
        flag = lambda r: float(((r > k) | (r < 1 / k)).mean())
        print(f"k {k}: hard foreground flagged {flag(hard):.3f}, background flagged {flag(bg):.4f}")


if __name__ == "__main__":
    main()

"""Procedural textures for the synthetic worlds, generated from a seed.

Each texture is an (H, W, 3) uint8 image drawn with numpy and OpenCV: multi-octave value
noise for low-frequency variation, plus shapes, lines and text at several scales so SIFT
finds corners and blobs everywhere (a blank wall would leave SfM and PnP nothing to match),
except `plain_wall`: the one deliberately textureless kind. Kinds take `(rng, h, w)` and most
an optional `color` (RGB 0-255) so the surfaces of one room can share a paint or a floor.
"""

from __future__ import annotations

import cv2
import numpy as np

FONTS = (cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_TRIPLEX,
         cv2.FONT_HERSHEY_COMPLEX)


def value_noise(rng: np.random.Generator, h: int, w: int, octaves: int = 4,
                base_cells: int = 4) -> np.ndarray:
    """(h, w) float32 noise in about [-1, 1]: random grids upsampled bicubically, summed
    over octaves with halving amplitude."""
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cells = base_cells * 2**o
        gh, gw = max(2, cells * h // max(h, w) + 1), max(2, cells * w // max(h, w) + 1)
        grid = rng.uniform(-1, 1, (gh, gw)).astype(np.float32)
        out += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
        amp *= 0.5
    return out / total


def _color(rng, lo=0, hi=255) -> tuple[int, int, int]:
    return tuple(int(c) for c in rng.integers(lo, hi, 3))


def _shade(base, noise: np.ndarray, strength: float) -> np.ndarray:
    img = np.asarray(base, np.float32)[None, None, :] * (1 + strength * noise[..., None])
    return np.clip(img, 0, 255).astype(np.uint8)


def scatter_marks(img: np.ndarray, rng: np.random.Generator, n: int, scale: float) -> None:
    """Draw `n` random filled/outlined circles, rectangles, polylines and words in place;
    `scale` is a typical mark size in pixels."""
    h, w = img.shape[:2]
    for _ in range(n):
        kind = rng.integers(0, 5)
        c = _color(rng)
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        s = max(2, int(scale * rng.uniform(0.3, 1.5)))
        thick = -1 if rng.random() < 0.5 else max(1, s // 8)
        if kind == 0:
            cv2.circle(img, (x, y), s, c, thick, cv2.LINE_AA)
        elif kind == 1:
            cv2.rectangle(img, (x, y), (x + s, y + int(s * rng.uniform(0.4, 2))), c, thick)
        elif kind == 2:
            pts = (np.array([x, y]) + rng.normal(0, s, (int(rng.integers(3, 6)), 2))).astype(np.int32)
            cv2.polylines(img, [pts], bool(rng.random() < 0.5), c, max(1, s // 6), cv2.LINE_AA)
        elif kind == 3:
            cv2.ellipse(img, (x, y), (s, max(1, s // 2)), float(rng.uniform(0, 180)), 0, 360, c,
                        thick, cv2.LINE_AA)
        else:
            word = "".join(chr(int(k)) for k in rng.integers(65, 91, int(rng.integers(2, 6))))
            cv2.putText(img, word, (x, y), FONTS[int(rng.integers(len(FONTS)))], s / 20, c,
                        max(1, s // 10), cv2.LINE_AA)


def painted_wall(rng, h, w, color=None) -> np.ndarray:
    """Light paint (`color`, else a random one) with posters and pinned notes."""
    img = _shade(_color(rng, 150, 230) if color is None else color, value_noise(rng, h, w, 5), 0.12)
    for _ in range(max(2, h * w // 40000)):  # posters
        pw, ph = max(2, int(rng.uniform(0.08, 0.25) * w)), max(2, int(rng.uniform(0.15, 0.4) * h))
        x, y = int(rng.integers(0, max(1, w - pw))), int(rng.integers(0, max(1, h - ph)))
        poster = _shade(_color(rng, 30, 255), value_noise(rng, ph, pw, 3), 0.4)
        scatter_marks(poster, rng, 12, max(4, min(pw, ph) / 6))
        img[y : y + ph, x : x + pw] = poster
        cv2.rectangle(img, (x, y), (x + pw, y + ph), (20, 20, 20), 2)
    scatter_marks(img, rng, h * w // 1500, 6)  # fine detail: ~4 cm marks at 160 texels/m
    scatter_marks(img, rng, h * w // 6000, 14)
    return img


def wood_floor(rng, h, w, color=None) -> np.ndarray:
    """Planks along x with grain, seams and scuffs; `color` (else random) is the wood."""
    img = _shade(_color(rng, 90, 170) if color is None else color, value_noise(rng, h, w, 5, 8), 0.25)
    plank = max(8, h // int(rng.integers(10, 20)))
    for y in range(0, h, plank):
        img[y : y + plank] = np.clip(img[y : y + plank] * rng.uniform(0.8, 1.2), 0, 255)
        cv2.line(img, (0, y), (w, y), (40, 30, 20), 2)
        for x in rng.integers(0, w, 2):
            cv2.line(img, (int(x), y), (int(x), y + plank), (40, 30, 20), 2)
    scatter_marks(img, rng, h * w // 2000, 6)
    scatter_marks(img, rng, h * w // 8000, plank / 2)
    return img


def ceiling_tiles(rng, h, w, color=None) -> np.ndarray:
    """Acoustic tiles on a grid, speckled; `color` (else random) is the tiles'."""
    img = _shade(_color(rng, 190, 240) if color is None else color, value_noise(rng, h, w, 4, 16), 0.15)
    speck = rng.random((h, w)) < 0.02
    img[speck] = (img[speck] * 0.6).astype(np.uint8)
    step = max(16, min(h, w) // 8)
    for x in range(0, w, step):
        cv2.line(img, (x, 0), (x, h), (120, 120, 120), 2)
    for y in range(0, h, step):
        cv2.line(img, (0, y), (w, y), (120, 120, 120), 2)
    scatter_marks(img, rng, h * w // 12000, step / 4)
    return img


def furniture(rng, h, w, color=None) -> np.ndarray:
    """Saturated surface (`color`, else random) with a printed pattern."""
    img = _shade(_color(rng, 40, 220) if color is None else color, value_noise(rng, h, w, 4), 0.3)
    scatter_marks(img, rng, max(20, h * w // 1200), 6)
    scatter_marks(img, rng, max(5, h * w // 6000), min(h, w) / 12)
    return img


def facade(rng, h, w) -> np.ndarray:
    """Brick courses with a grid of windows (rows of ~3 m storeys)."""
    img = _shade(_color(rng, 110, 200), value_noise(rng, h, w, 5, 8), 0.2)
    course = max(4, h // 60)
    for i, y in enumerate(range(0, h, course)):
        cv2.line(img, (0, y), (w, y), (70, 70, 70), 1)
        for x in range((i % 2) * course, w, 2 * course):
            cv2.line(img, (x, y), (x, y + course), (70, 70, 70), 1)
    storey = max(20, h // max(1, round(h / (w / 4 + 1))))
    for y in range(storey // 4, h - storey // 2, storey):
        for x in range(int(storey * 0.3), w - storey // 2, storey):
            ww, wh = int(storey * rng.uniform(0.35, 0.55)), int(storey * rng.uniform(0.45, 0.6))
            cv2.rectangle(img, (x, y), (x + ww, y + wh), _color(rng, 20, 120), -1)
            cv2.rectangle(img, (x, y), (x + ww, y + wh), (230, 230, 230), max(1, storey // 30))
    scatter_marks(img, rng, h * w // 6000, storey / 6)
    return img


def ground(rng, h, w) -> np.ndarray:
    """Paving slabs over grass-like noise."""
    g = value_noise(rng, h, w, 6, 16)
    img = _shade(_color(rng, 80, 160), g, 0.35)
    step = max(12, min(h, w) // 20)
    for x in range(0, w, step):
        cv2.line(img, (x, 0), (x, h), (60, 60, 60), 1)
    for y in range(0, h, step):
        cv2.line(img, (0, y), (w, y), (60, 60, 60), 1)
    scatter_marks(img, rng, h * w // 3000, step / 2)
    return img


def plain_wall(rng, h, w, color=None) -> np.ndarray:
    """Uniform matt paint with no marks at all: a textureless wall, where SIFT finds
    nothing (what feature matching and photo likelihoods must survive)."""
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _color(rng, 170, 240) if color is None else color
    return img


def wallpaper(rng, h, w, color=None) -> np.ndarray:
    """Striped paper (`color`, else random) with a small printed motif on a lattice, plus
    scattered marks so no two places of it look the same."""
    base = np.asarray(_color(rng, 120, 230) if color is None else color, np.float32)
    img = _shade(base, value_noise(rng, h, w, 4), 0.08)
    stripe = max(6, w // int(rng.integers(12, 30)))
    dark = tuple(int(c) for c in base * rng.uniform(0.6, 0.85))
    for x in range(0, w, 2 * stripe):
        img[:, x : x + stripe] = (img[:, x : x + stripe] * rng.uniform(0.85, 0.95)).astype(np.uint8)
    step = 2 * stripe
    ink = _color(rng, 20, 160)
    for y in range(step // 2, h, step):
        for x in range(step // 2 + (y // step % 2) * stripe, w, step):
            cv2.circle(img, (x, y), max(2, stripe // 4), ink, -1, cv2.LINE_AA)
            cv2.circle(img, (x, y), max(3, stripe // 2), dark, 1, cv2.LINE_AA)
    scatter_marks(img, rng, h * w // 3000, 6)
    scatter_marks(img, rng, h * w // 12000, 14)
    return img


def floor_tiles(rng, h, w, color=None) -> np.ndarray:
    """Ceramic tiles with grout lines, each tile a little different, a few scuffs."""
    base = np.asarray(_color(rng, 100, 230) if color is None else color, np.float32)
    img = _shade(base, value_noise(rng, h, w, 5, 8), 0.1)
    step = max(16, int(min(h, w) / rng.uniform(6, 12)))
    for y in range(0, h, step):
        for x in range(0, w, step):
            img[y : y + step, x : x + step] = np.clip(img[y : y + step, x : x + step]
                                                      * rng.uniform(0.85, 1.15), 0, 255)
    grout = tuple(int(c) for c in base * 0.5)
    for x in range(0, w, step):
        cv2.line(img, (x, 0), (x, h), grout, 2)
    for y in range(0, h, step):
        cv2.line(img, (0, y), (w, y), grout, 2)
    scatter_marks(img, rng, h * w // 2500, 5)
    scatter_marks(img, rng, h * w // 10000, step / 3)
    return img


def carpet(rng, h, w, color=None) -> np.ndarray:
    """Fibrous carpet (`color`, else random) with a woven border pattern and stains."""
    base = _color(rng, 60, 200) if color is None else color
    img = _shade(base, value_noise(rng, h, w, 6, 16), 0.3)
    fibre = rng.normal(0, 14, (h, w, 1)).astype(np.float32)
    img = np.clip(img + fibre, 0, 255).astype(np.uint8)
    step = max(10, min(h, w) // int(rng.integers(8, 16)))
    ink = _color(rng, 20, 235)
    for y in range(step // 2, h, step):
        for x in range(step // 2, w, step):
            d = step // 3
            cv2.polylines(img, [np.array([(x, y - d), (x + d, y), (x, y + d), (x - d, y)], np.int32)],
                          True, ink, 1, cv2.LINE_AA)
    scatter_marks(img, rng, h * w // 2500, 6)
    return img


KINDS = {f.__name__: f for f in (painted_wall, wood_floor, ceiling_tiles, furniture, facade, ground,
                                   plain_wall, wallpaper, floor_tiles, carpet)}

"""Issue 28, item 5: what Zhao's hybrid could gain, estimated from images
already rendered, before building it. A 16x16 tile takes `fast`'s pixels
where its gather window (dilated as fast dilates it: the largest CoC/2 of
the tiles that reach it) is one surface -- every pixel's CoC within
max(abs_px, rel * largest CoC) of the others, and no mix of background and
surface -- and `layered2`'s elsewhere. Prints the share of one-surface
tiles and the composite's PSNR against Mitsuba's reference.

usage: python hybrid_estimate.py WORK_DIR ZC_EXR
  WORK_DIR: a scene's work directory of scripts/bench-vs-mitsuba
            (pointlens_fast.exr, pointlens_layered2.exr, mitsuba_ref_1024spp.exr)
  ZC_EXR:   pointlens `render --method pinhole --passes z,coc` of the same camera
Needs numpy and mitsuba (to read EXR), e.g. the venv of scripts/gaussians-vs-mitsuba.
"""
import sys

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
TILE = 16


def load(path):
    return np.array(mi.Bitmap(path), dtype=np.float64)


def psnr(image, ref):
    return 10 * np.log10(1.0 / np.mean((np.clip(image, 0, None) - ref) ** 2))


def main(work, zc_path):
    ref = load(f"{work}/mitsuba_ref_1024spp.exr")[..., :3]
    fast = load(f"{work}/pointlens_fast.exr")[..., :3]
    layered = load(f"{work}/pointlens_layered2.exr")[..., :3]
    zc = load(zc_path)  # R, G, B, Z, A, CoC
    z, coc = zc[..., 3], zc[..., 5]
    h, w = coc.shape
    th, tw = -(-h // TILE), -(-w // TILE)
    pad = lambda a, v: np.pad(a, ((0, th * TILE - h), (0, tw * TILE - w)), constant_values=v)
    tiles = lambda a: a.reshape(th, TILE, tw, TILE)
    c = tiles(pad(coc, np.nan))
    background = tiles(~np.isfinite(pad(z, np.inf)))
    c_max, c_min = np.nanmax(c, axis=(1, 3)), np.nanmin(c, axis=(1, 3))
    any_bg, all_bg = background.any(axis=(1, 3)), background.all(axis=(1, 3))
    ys, xs = np.mgrid[0:th, 0:tw]
    # Distance in pixels from tile (y, x) to the nearest pixel of each tile.
    dist = lambda y, x: np.maximum(np.hypot(ys - y, xs - x) - 1.5, 0) * TILE
    radius = np.array([[(c_max / 2)[dist(y, x) <= c_max / 2].max() for x in range(tw)] for y in range(th)])
    windows = [[dist(y, x) <= radius[y, x] for x in range(tw)] for y in range(th)]
    print(f"fast {psnr(fast, ref):.2f} dB, layered2 {psnr(layered, ref):.2f} dB (against Mitsuba 1024 spp)")
    for rel in [0.0, 0.25, 0.5]:
        for abs_px in [1.0, 2.0, 4.0]:
            one = np.zeros((th, tw), bool)
            for y in range(th):
                for x in range(tw):
                    m = windows[y][x]
                    hi, lo = c_max[m].max(), c_min[m].min()
                    mixed = any_bg[m].any() and not all_bg[m].all()
                    one[y, x] = hi - lo <= max(abs_px, rel * hi) and not mixed
            mask = np.repeat(np.repeat(one, TILE, 0), TILE, 1)[:h, :w]
            hybrid = np.where(mask[..., None], fast, layered)
            print(f"rel {rel:.2f} abs {abs_px:.0f} px: one-surface tiles {100 * one.mean():.1f} %"
                  f" (all background {100 * (one & all_bg).mean():.1f} %), hybrid {psnr(hybrid, ref):.2f} dB")


if __name__ == "__main__":
    main(*sys.argv[1:3])

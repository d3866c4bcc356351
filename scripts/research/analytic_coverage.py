"""A CPU estimate of the analytic-coverage resolve (docs/bench/gbuffer-error.md):
the pinhole G-buffer's K×K samples only find the splats near a pixel; its
colour is then each candidate's exact visible area in the pixel box (the
squares face the camera at one depth each and are aligned with the pixel
grid, so front-to-back visibility is an inclusion–exclusion of rectangles).

For each scene of gbuffer_error.py's work directory (its camera, splats and
Mitsuba pinhole reference): the splats projected as pointlens's sprites
are (side f·d/z, at least a pixel), K×K samples at cell centres with the
nearest splat each (ties to the earlier splat), then

- `samples`: the mean of the samples (pointlens's K×K image; checked
  against pointlens --raster sprites --ssaa K);
- `analytic`: per pixel, the nearest NEAR candidates among the splats its
  own and its 8 neighbours' samples saw, each weighted by its exact
  visible area in the pixel; the part no candidate covers is background
  where one of the pixel's samples saw background, else shared out in
  proportion (as sampling would).

Prints PSNR against Mitsuba's 1024-spp image. Run with the venv's Python:

    ~/.cache/pointlens/venv-mitsuba/bin/python scripts/research/analytic_coverage.py \\
        --work /tmp/gbuffer-error [--scenes bunny,mug,autzen] [--k 3]
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "mitsuba"))
import splat_scene as ss  # noqa: E402
from bench import psnr_np  # noqa: E402

NEAR = 8


def project(cam, positions, diameters):
    """Per splat: x0, x1, y0, y1 (pixels) and eye depth z; NaN where behind."""
    eye, right, up, forward = ss.camera_basis(cam)
    e = positions.astype(np.float64) - eye
    z = e @ forward
    f = ss.f_px(cam)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = cam["width"] / 2.0 + f * (e @ right) / z
        y = cam["height"] / 2.0 - f * (e @ up) / z
        side = np.maximum(f * diameters / z, 1.0)
    h = side / 2.0
    rect = np.stack([x - h, x + h, y - h, y + h], axis=1)
    rect[z <= 0] = np.nan
    return rect, z


def offsets(k, rotated):
    """The K×K samples' positions in a pixel, by target cell (i, j): cell
    centres, or the compute rasteriser's rotated grid
    ((i + 1 − (j + ½)/K)/K, (j + (i + ½)/K)/K)."""
    cells = [(i, j) for j in range(k) for i in range(k)]
    if rotated:
        return [(i, j, (i + 1 - (j + 0.5) / k) / k, (j + (i + 0.5) / k) / k) for i, j in cells]
    return [(i, j, (i + 0.5) / k, (j + 0.5) / k) for i, j in cells]


def sample_ids(rect, z, width, height, k, rotated=False):
    """The id of the nearest splat at each of the K×K samples of every
    pixel, as a (H·K) × (W·K) target (cell (i, j) of pixel p at K·p + (i,
    j); −1: background), ties to the lower id."""
    ids = np.full((height * k, width * k), -1, np.int64)
    # Nearest and earliest written last: descending (z, id).
    order = np.lexsort((-np.arange(len(z)), -z))
    order = order[np.isfinite(rect[order, 0])]
    r = rect[order]
    for i, j, ax, ay in offsets(k, rotated):
        # Pixel px's sample at px + ax lies in [x0, x1) when
        # x0 − ax <= px < x1 − ax.
        px0 = np.clip(np.ceil(r[:, 0] - ax), 0, width).astype(np.int64)
        px1 = np.clip(np.ceil(r[:, 1] - ax), 0, width).astype(np.int64)
        py0 = np.clip(np.ceil(r[:, 2] - ay), 0, height).astype(np.int64)
        py1 = np.clip(np.ceil(r[:, 3] - ay), 0, height).astype(np.int64)
        plane = np.full((height, width), -1, np.int64)
        for n in np.flatnonzero((px1 > px0) & (py1 > py0)):
            plane[py0[n]:py1[n], px0[n]:px1[n]] = order[n]
        ids[j::k, i::k] = plane
    return ids


def samples_image(ids, colors, k, background):
    H, W = ids.shape
    c = np.where(ids[..., None] >= 0, colors[np.maximum(ids, 0)], background)
    return c.reshape(H // k, k, W // k, k, 3).mean(axis=(1, 3))


def analytic_image(ids, rect, z, colors, k, background):
    H, W = ids.shape
    h, w = H // k, W // k
    per_pixel = ids.reshape(h, k, w, k).transpose(0, 2, 1, 3).reshape(h, w, k * k)
    saw_background = (per_pixel < 0).any(axis=2)
    pad = np.pad(per_pixel, ((1, 1), (1, 1), (0, 0)), constant_values=-1)
    around = np.concatenate([pad[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)], axis=2)
    around = around.reshape(h * w, -1)
    # Distinct candidates, nearest first: repeats dropped (sorted by id),
    # then the nearest NEAR by (z, id).
    a_sorted = np.sort(around, axis=1)
    dup = np.zeros_like(a_sorted, bool)
    dup[:, 1:] = a_sorted[:, 1:] == a_sorted[:, :-1]
    # Only those whose square reaches into the pixel's box.
    py, px = np.divmod(np.arange(h * w), w)
    ra = rect[np.maximum(a_sorted, 0)]
    reaches = ((np.minimum(ra[..., 1], px[:, None] + 1.0) > np.maximum(ra[..., 0], px[:, None]))
               & (np.minimum(ra[..., 3], py[:, None] + 1.0) > np.maximum(ra[..., 2], py[:, None])))
    z_sorted = np.where(dup | (a_sorted < 0) | ~reaches, np.inf, z[np.maximum(a_sorted, 0)])
    del ra, reaches
    key2 = np.argsort(z_sorted, axis=1, kind="stable")[:, :NEAR]
    cand = np.take_along_axis(a_sorted, key2, axis=1)
    valid = np.isfinite(np.take_along_axis(z_sorted, key2, axis=1))
    # Each candidate's rectangle clipped to its pixel box.
    r = rect[np.maximum(cand, 0)]
    x0 = np.clip(r[..., 0] - px[:, None], 0.0, 1.0)
    x1 = np.clip(r[..., 1] - px[:, None], 0.0, 1.0)
    y0 = np.clip(r[..., 2] - py[:, None], 0.0, 1.0)
    y1 = np.clip(r[..., 3] - py[:, None], 0.0, 1.0)
    x1 = np.where(valid, x1, x0)
    # vis_k: the sum over subsets whose last member is k of ±area(∩).
    n = cand.shape[1]
    vis = np.zeros((h * w, n))
    for mask in range(1, 1 << n):
        members = [j for j in range(n) if mask >> j & 1]
        last = members[-1]
        ix0 = np.max(x0[:, members], axis=1)
        ix1 = np.min(x1[:, members], axis=1)
        iy0 = np.max(y0[:, members], axis=1)
        iy1 = np.min(y1[:, members], axis=1)
        area = np.maximum(ix1 - ix0, 0) * np.maximum(iy1 - iy0, 0)
        vis[:, last] += area if len(members) % 2 else -area
    vis = np.maximum(vis, 0.0)
    covered = vis.sum(axis=1)
    col = (vis[..., None] * colors[np.maximum(cand, 0)]).sum(axis=1)
    bg = saw_background.ravel()
    rest = np.clip(1.0 - covered, 0.0, 1.0)
    out = np.where(bg[:, None], col + rest[:, None] * background,
                   col / np.maximum(covered, 1e-12)[:, None])
    out = np.where((covered <= 0)[:, None], background, out)
    return out.reshape(h, w, 3)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--work", required=True)
    p.add_argument("--scenes", default="bunny,mug,autzen")
    p.add_argument("--k", type=int, default=3)
    p.add_argument("--rotated", action="store_true", help="the compute rasteriser's rotated grid")
    args = p.parse_args()
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    for scene in args.scenes.split(","):
        d = Path(args.work) / scene
        cam = json.loads((d / "camera.json").read_text())
        positions, diameters, colors = ss.read_splats(d / "splats.bin")
        ref = np.array(mi.Bitmap(str(d / "mitsuba_pinhole_1024.exr")), np.float32)[..., :3]
        rect, z = project(cam, positions, diameters)
        bgc = np.zeros(3)
        print(f"{scene}:")
        for k in sorted({args.k, 8}):
            ids = sample_ids(rect, z, cam["width"], cam["height"], k, args.rotated)
            s = samples_image(ids, colors, k, bgc)
            line = f"  K = {k}: samples {psnr_np(s, ref):.2f} dB"
            if k == args.k:
                a = analytic_image(ids, rect, z, colors, k, bgc)
                line += f", analytic {psnr_np(a, ref):.2f} dB"
            print(line)
            if (d / f"pinhole_k{k}_sprites.exr").exists():
                pl = np.array(mi.Bitmap(str(d / f"pinhole_k{k}_sprites.exr")), np.float32)[..., :3]
                print(f"    (the samples image against pointlens --raster sprites: {psnr_np(s, pl):.2f} dB)")


if __name__ == "__main__":
    main()

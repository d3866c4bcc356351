"""Where the G-buffer's error against the exact pixel integral lies
(docs/bench/gbuffer-error.md): each bundled scene's pinhole image at
K = 1…8 by the samples' mean (`--coverage samples`; every splat,
`--lod-px 0`; and by area at K = 3 and 4, the default) against Mitsuba 3's pinhole render of
the same squares at REF_SPP (box filter: the pixel-area integral), its
squared error (sRGB, as bench-vs-mitsuba's PSNR) split by pixel class:

- interior: the K = 8 and K = 1 colours agree (every sample one colour:
  what more samples cannot change), and no depth step;
- surface edge: the colours differ, the depths around the pixel do not
  step (splat borders on one surface: the squares' own edges);
- depth step: the 3×3 pixels' K = 1 eye depths differ by more than
  STEP_REL of the nearest, or one is background (silhouettes);
- background: K = 1 and K = 8 see nothing (no error expected).

Prints a Markdown table per scene and writes, for the first scene, the
class map and the K = 3 error image as PNGs. Run with the venv's Python:

    ~/.cache/pointlens/venv-mitsuba/bin/python scripts/research/gbuffer_error.py \\
        --pointlens PATH --export-splats PATH --work DIR [--images DIR] [--size WxH]
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "mitsuba"))
import splat_scene as ss  # noqa: E402
from bench import SCENES, psnr_np, srgb  # noqa: E402

REF_SPP = 1024
KS = [1, 2, 3, 4, 6, 8]
STEP_REL = 0.03
CLASSES = ["interior", "surface edge", "depth step", "background"]


def run(cmd):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{cmd[0]} failed: {r.stderr.strip()}")
    return r.stdout


def read(mi, path, channels=None):
    b = mi.Bitmap(str(path))
    if channels is None:
        return np.array(b, dtype=np.float32)[:, :, :3]
    names = [b.struct_()[i].name for i in range(b.channel_count())]
    return np.array(b, dtype=np.float32)[:, :, names.index(channels)]


def classes(c1, c8, z1):
    """The class index of each pixel (CLASSES)."""
    h, w = z1.shape
    pad = np.pad(z1, 1, mode="edge")
    near = np.full_like(z1, np.inf)
    far = np.full_like(z1, -np.inf)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            n = pad[dy:dy + h, dx:dx + w]
            near = np.minimum(near, n)
            far = np.maximum(far, n)
    with np.errstate(invalid="ignore"):
        step = ~np.isfinite(far) | (far - near > STEP_REL * near)
    differ = np.abs(c8 - c1).max(axis=2) > 1.0 / 1024.0
    out = np.where(differ, 1, 0)
    out = np.where(step & (differ | ~np.isfinite(z1)), 2, out)
    out = np.where(~np.isfinite(near), 3, out)
    return out


def study(args, mi, dr, scene):
    d = Path(args.work) / scene
    d.mkdir(parents=True, exist_ok=True)
    ply = Path(args.repo) / SCENES[scene]["file"]
    flags = list(SCENES[scene]["flags"])
    if "--aperture-radius" in flags:
        i = flags.index("--aperture-radius")
        del flags[i:i + 2]
    width, height = args.size.split("x")
    size = ["--width", width, "--height", height]
    cam = json.loads(run([args.pointlens, "render", ply, "-o", d / "probe.exr", "--method", "pinhole",
                          *size, *flags, "--print-camera"]))
    # A pinhole: Mitsuba's `perspective` sensor (the printed camera has the
    # default lens's radius, which pinhole ignores).
    cam["aperture_radius"] = 0.0
    (d / "camera.json").write_text(json.dumps(cam))
    splats = d / "splats.bin"
    run([args.export_splats, ply, splats])
    positions, diameters, colors = ss.read_splats(splats)
    ref_path = d / f"mitsuba_pinhole_{REF_SPP}.exr"
    if not ref_path.exists():
        mscene, _ = ss.build_scene(mi, cam, positions, diameters, colors)
        total = None
        for k in range(REF_SPP // 64):
            img, _ = ss.render(mi, dr, mscene, 64, 1000 + k)
            total = img if total is None else total + img
        ss.write_exr(mi, ref_path, total / (REF_SPP // 64))
        del mscene
    ref = read(mi, ref_path)
    images = {}
    # The samples' G-buffer at each K (the study's subject), and the
    # default's area coverage at K = 3 and 4 beside it.
    pinhole = [args.pointlens, "render", ply, "--camera", d / "camera.json", "--method", "pinhole",
               "--lod-px", "0", "--passes", "z"]
    for k in KS:
        out = d / f"pinhole_k{k}.exr"
        run(pinhole + ["-o", out, "--ssaa", str(k), "--coverage", "samples"])
        images[k] = out
    area = []
    for k in (3, 4):
        out = d / f"pinhole_area_k{k}.exr"
        run(pinhole + ["-o", out, "--ssaa", str(k), "--coverage", "area"])
        area.append((k, psnr_np(read(mi, out), ref)))
    c1, c8 = read(mi, images[1]), read(mi, images[8])
    z1 = read(mi, images[1], "Z")
    cls = classes(c1, c8, z1)
    rows = []
    for k in KS:
        img = read(mi, images[k])
        err = ((srgb(img) - srgb(ref)) ** 2).mean(axis=2)
        total = err.sum()
        shares = [err[cls == c].sum() / total for c in range(len(CLASSES))]
        rows.append((k, psnr_np(img, ref), shares, err))
    pixels = [float((cls == c).mean()) for c in range(len(CLASSES))]
    # What edge-adaptive samples could reach: K = 8 where the K = 3 pixel
    # differs from its centre sample (K = 1: a stand-in for "the nine
    # samples disagree"), K = 3 elsewhere.
    c3 = read(mi, images[3])
    marked = np.abs(c3 - c1).max(axis=2) > 1.0 / 1024.0
    estimates = []
    for grow in (0, 1):
        m = marked.copy()
        for _ in range(grow):
            pad = np.pad(m, 1)
            h, w = m.shape
            m = np.zeros_like(m)
            for dy in (0, 1, 2):
                for dx in (0, 1, 2):
                    m |= pad[dy:dy + h, dx:dx + w]
        adaptive = np.where(m[:, :, None], c8, c3)
        estimates.append((grow, psnr_np(adaptive, ref), float(m.mean())))
    return cls, rows, pixels, estimates, area


def frame_size(text):
    """`--size`: WIDTHxHEIGHT, two positive integers (argparse's one-line
    error otherwise)."""
    parts = text.split("x")
    if len(parts) != 2 or not all(p.isdigit() and int(p) > 0 for p in parts):
        raise argparse.ArgumentTypeError(f"'{text}' is not WIDTHxHEIGHT (e.g. 1920x1080)")
    return text


def png(mi, path, rgb):
    mi.Bitmap(np.ascontiguousarray(rgb.astype(np.float32))).convert(
        mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(str(path))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--pointlens", required=True)
    p.add_argument("--export-splats", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--repo", default=str(HERE.parent.parent))
    p.add_argument("--scenes", default="bunny,mug,autzen")
    p.add_argument("--size", default="640x480", type=frame_size, help="the frames' WIDTHxHEIGHT")
    p.add_argument("--images", default=None)
    args = p.parse_args()
    import mitsuba as mi
    import drjit as dr
    mi.set_variant("llvm_ad_rgb")
    for n, scene in enumerate(args.scenes.split(",")):
        cls, rows, pixels, estimates, area = study(args, mi, dr, scene)
        print(f"\n### {scene} ({args.size.replace('x', '×')}, every splat, Mitsuba {REF_SPP} spp pinhole)\n")
        print("pixels: " + ", ".join(f"{c} {100 * s:.1f} %" for c, s in zip(CLASSES, pixels)) + "\n")
        print("| K | PSNR | " + " | ".join(f"{c} share of the error" for c in CLASSES[:3])
              + " | PSNR with edges exact | PSNR with depth steps exact |")
        print("|---:|---:|" + "---:|" * 5)
        for k, psnr, shares, err in rows:
            mse = err.mean()
            no_edge = 10 * np.log10(1 / (mse * (1 - shares[1]))) if shares[1] < 1 else float("inf")
            no_step = 10 * np.log10(1 / (mse * (1 - shares[2]))) if shares[2] < 1 else float("inf")
            print(f"| {k} | {psnr:.2f} | " + " | ".join(f"{100 * s:.1f} %" for s in shares[:3])
                  + f" | {no_edge:.2f} | {no_step:.2f} |")
        for grow, adaptive_psnr, marked in estimates:
            print(f"\nK = 8 where K = 3 differs from K = 1 (grown by {grow} px: {100 * marked:.1f} % "
                  f"of the pixels), K = 3 elsewhere: {adaptive_psnr:.2f} dB")
        print("\nBy area (`--coverage area`): " + ", ".join(f"K = {k} {p:.2f} dB" for k, p in area))
        if args.images and n == 0:
            out = Path(args.images)
            out.mkdir(parents=True, exist_ok=True)
            palette = np.array([[0.05, 0.05, 0.05], [0.1, 0.6, 1.0], [1.0, 0.45, 0.1], [0, 0, 0]], np.float32)
            png(mi, out / f"{scene}_classes.png", palette[cls] ** 2.2)
            # The sRGB error amplitude, ten times (0.1 white), K = 3 and K = 8.
            for k in (3, 8):
                err = next(e for kk, _, _, e in rows if kk == k)
                amp = np.clip(10.0 * np.sqrt(err), 0.0, 1.0)
                png(mi, out / f"{scene}_error_k{k}.png", np.repeat(amp[:, :, None], 3, axis=2) ** 2.2)

if __name__ == "__main__":
    main()

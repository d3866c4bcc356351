"""Fits 3D Gaussians to views of a point cloud: a small trained 3DGS scene
for pointlens's tests and figures (run by scripts/gaussians-train; see
there). Not a dependency of the tests.

The model is the reference rasterizer's as pointlens's CPU reference
(src/gaussians.rs) writes it, in pointlens's camera (DESIGN §2): eye-space
centres culled at z <= 0.2; Σ = R S Sᵀ Rᵀ; the 2D covariance through the
Jacobian at the centre (x/z, y/z clamped to 1.3 × the half field of view's
tangent) plus 0.3 px²; the 3σ radius and the 16-px tiles its square
covers (a Gaussian adds only in those tiles); the colour from SH of degree
3 at the direction camera → centre, + 0.5, clamped at 0; α = min(0.99,
o·e^power), none where power > 0 or α < 1/255; front to back by eye depth
over the background. The values are sRGB-encoded, as the views (pointlens
PNGs) are. The stop at transmittance 10⁻⁴ is left out of the fit: where a
pixel's Gaussians bring it that low, what the reference leaves out (the
stopping Gaussian and all behind it, at most T·|c − background| with T
up to 10⁻²) is kept here.

Training is plain: a fixed set of Gaussians initialised from the cloud's
splats (examples/export_splats: centres, world diameters, linear colours),
one view per step, L1 loss, Adam with the reference code's learning rates
(the centres' decaying exponentially), no densification or pruning during
training; Gaussians left nearly transparent are dropped at the end. Every
pixel is composited against every Gaussian (dense, in chunks of pixels):
fine for tens of thousands of Gaussians on a GPU or a small one on a CPU.

Writes the reference code's PLY layout (binary little endian: x y z, nx ny
nz (zero), f_dc_0..2, f_rest_0..44 channel-major, opacity (logit),
scale_0..2 (log), rot_0..3 (w, x, y, z)).
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from PIL import Image

# The splat file's reader and the camera's basis, as the Mitsuba scripts
# read them.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "mitsuba"))
import splat_scene  # noqa: E402

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)
TILE = 16


def log(msg):
    print(f"[gaussians-train] {msg}", file=sys.stderr, flush=True)


def srgb_encode(c):
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def load_views(folder):
    views = []
    for js in sorted(Path(folder).glob("v*.json")):
        cam = json.loads(js.read_text())
        img = np.asarray(Image.open(js.with_suffix(".png")).convert("RGB"), np.float32) / 255.0
        eye, right, up, fwd = splat_scene.camera_basis(cam)
        f_px = splat_scene.f_px(cam)
        if img.shape[:2] != (cam["height"], cam["width"]):
            raise SystemExit(f"{js}: the image is not {cam['width']}x{cam['height']}")
        views.append({"eye": eye.astype(np.float32), "w": np.stack([right, up, fwd]).astype(np.float32),
                      "f": np.float32(f_px), "image": img, "name": js.stem})
    if not views:
        raise SystemExit(f"{folder}: no views (vNN.json + vNN.png)")
    sizes = {v["image"].shape for v in views}
    if len(sizes) != 1:
        raise SystemExit(f"{folder}: views of different sizes {sizes}")
    return views


def quat_to_mat(q):
    q = q / jnp.linalg.norm(q, axis=1, keepdims=True)
    r, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return jnp.stack([
        jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - r * z), 2 * (x * z + r * y)], -1),
        jnp.stack([2 * (x * y + r * z), 1 - 2 * (x * x + z * z), 2 * (y * z - r * x)], -1),
        jnp.stack([2 * (x * z - r * y), 2 * (y * z + r * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


def sh_color(sh, d):
    """sh: (N, 16, 3), d: (N, 3) unit directions."""
    x, y, z = d[:, 0:1], d[:, 1:2], d[:, 2:3]
    c = lambda k: sh[:, k, :]  # noqa: E731
    res = SH_C0 * c(0) - SH_C1 * y * c(1) + SH_C1 * z * c(2) - SH_C1 * x * c(3)
    xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
    res = (res + SH_C2[0] * xy * c(4) + SH_C2[1] * yz * c(5) + SH_C2[2] * (2 * zz - xx - yy) * c(6)
           + SH_C2[3] * xz * c(7) + SH_C2[4] * (xx - yy) * c(8))
    res = (res + SH_C3[0] * y * (3 * xx - yy) * c(9) + SH_C3[1] * xy * z * c(10)
           + SH_C3[2] * y * (4 * zz - xx - yy) * c(11) + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * c(12)
           + SH_C3[4] * x * (4 * zz - xx - yy) * c(13) + SH_C3[5] * z * (xx - yy) * c(14)
           + SH_C3[6] * x * (xx - 3 * yy) * c(15))
    return jnp.maximum(res + 0.5, 0.0)


def project(p, eye, w, f, width, height):
    """Per Gaussian: centre px, conic (a, b, c), tile box, depth, colour,
    opacity, and whether it is drawn."""
    means, scales, quats = p["means"], jnp.exp(p["log_scales"]), p["quats"]
    e = (means - eye) @ w.T
    z = e[:, 2]
    valid = z > 0.2
    zs = jnp.where(valid, z, 1.0)
    rot = quat_to_mat(quats)
    m = rot * scales[:, None, :]
    sigma = m @ jnp.swapaxes(m, 1, 2)
    lim_x = 1.3 * width / (2 * f)
    lim_y = 1.3 * height / (2 * f)
    tx = jnp.clip(e[:, 0] / zs, -lim_x, lim_x) * zs
    ty = jnp.clip(e[:, 1] / zs, -lim_y, lim_y) * zs
    zero = jnp.zeros_like(zs)
    j = jnp.stack([
        jnp.stack([f / zs, zero, -f * tx / (zs * zs)], -1),
        jnp.stack([zero, -f / zs, f * ty / (zs * zs)], -1),
    ], 1)
    t = j @ w
    cov = t @ sigma @ jnp.swapaxes(t, 1, 2)
    a, b, c = cov[:, 0, 0] + 0.3, cov[:, 0, 1], cov[:, 1, 1] + 0.3
    det = a * c - b * b
    valid = valid & (det > 0)
    det = jnp.where(valid, det, 1.0)
    conic = jnp.stack([c / det, -b / det, a / det], -1)
    mid = 0.5 * (a + c)
    lam = mid + jnp.sqrt(jnp.maximum(mid * mid - det, 0.1))
    radius = jax.lax.stop_gradient(jnp.ceil(3 * jnp.sqrt(lam)))
    cx = width / 2 + f * e[:, 0] / zs
    cy = height / 2 - f * e[:, 1] / zs
    gx, gy = (width + TILE - 1) // TILE, (height + TILE - 1) // TILE
    ax, ay = jax.lax.stop_gradient(cx - 0.5), jax.lax.stop_gradient(cy - 0.5)
    lo_x = jnp.floor(jnp.clip((ax - radius) / TILE, 0, gx))
    hi_x = jnp.floor(jnp.clip((ax + radius + TILE - 1) / TILE, 0, gx))
    lo_y = jnp.floor(jnp.clip((ay - radius) / TILE, 0, gy))
    hi_y = jnp.floor(jnp.clip((ay + radius + TILE - 1) / TILE, 0, gy))
    valid = valid & ((hi_x - lo_x) * (hi_y - lo_y) > 0)
    d = means - eye
    d = d / jnp.linalg.norm(d, axis=1, keepdims=True)
    color = sh_color(p["sh"], d)
    opacity = jax.nn.sigmoid(p["opacity"])
    return {"cx": cx, "cy": cy, "conic": conic, "box": jnp.stack([lo_x, hi_x, lo_y, hi_y], -1),
            "z": z, "color": color, "opacity": opacity, "valid": valid}


def composite(g, pix, tiles, background):
    """Pixels `pix` (P, 2: centres), their tiles (P, 2), against the
    Gaussians `g` sorted front to back."""
    dx = g["cx"][None, :] - pix[:, 0:1]
    dy = g["cy"][None, :] - pix[:, 1:2]
    a, b, c = g["conic"][:, 0], g["conic"][:, 1], g["conic"][:, 2]
    power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
    box = g["box"]
    inside = ((tiles[:, 0:1] >= box[None, :, 0]) & (tiles[:, 0:1] < box[None, :, 1])
              & (tiles[:, 1:2] >= box[None, :, 2]) & (tiles[:, 1:2] < box[None, :, 3]) & g["valid"][None, :])
    alpha = jnp.minimum(0.99, g["opacity"][None, :] * jnp.exp(jnp.minimum(power, 0.0)))
    alpha = jnp.where(inside & (power <= 0) & (alpha >= 1 / 255), alpha, 0.0)
    trans = jnp.cumprod(1 - alpha, axis=1)
    before = jnp.concatenate([jnp.ones_like(trans[:, :1]), trans[:, :-1]], axis=1)
    weight = alpha * before
    return weight @ g["color"] + trans[:, -1:] * background


def make_render(width, height, chunk):
    ys, xs = np.mgrid[0:height, 0:width]
    pix = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], -1).astype(np.float32)
    tiles = np.stack([xs.ravel() // TILE, ys.ravel() // TILE], -1).astype(np.float32)
    n = pix.shape[0]
    pad = (-n) % chunk
    pix = np.concatenate([pix, np.zeros((pad, 2), np.float32)]).reshape(-1, chunk, 2)
    tiles = np.concatenate([tiles, np.full((pad, 2), -1, np.float32)]).reshape(-1, chunk, 2)

    def render(p, eye, w, f, background):
        g = project(p, eye, w, f, width, height)
        order = jnp.argsort(jnp.where(g["valid"], g["z"], jnp.inf))
        g = {k: v[order] for k, v in g.items()}
        body = jax.checkpoint(lambda pt: composite(g, pt[0], pt[1], background))
        out = jax.lax.map(body, (jnp.asarray(pix), jnp.asarray(tiles)))
        return out.reshape(-1, 3)[:n].reshape(height, width, 3)

    return render


def init_params(splats, count, seed):
    positions, diameters, colors = splats
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(positions), size=min(count, len(positions)), replace=False)
    pick.sort()
    pos = positions[pick]
    # Each kept splat stands for len/count of them: a radius that covers
    # their share of the surface.
    cover = math.sqrt(len(positions) / len(pick))
    scale = np.maximum(diameters[pick] * 0.5 * cover * 0.6, 1e-3)
    dc = (srgb_encode(colors[pick]) - 0.5) / SH_C0
    sh = np.zeros((len(pick), 16, 3), np.float32)
    sh[:, 0, :] = dc
    return {
        "means": jnp.asarray(pos, jnp.float32),
        "log_scales": jnp.asarray(np.log(np.repeat(scale[:, None], 3, 1)), jnp.float32),
        "quats": jnp.asarray(np.tile([1.0, 0.0, 0.0, 0.0], (len(pick), 1)), jnp.float32),
        "opacity": jnp.full((len(pick),), math.log(0.8 / 0.2), jnp.float32),
        "sh": jnp.asarray(sh),
    }


def write_ply(path, p, min_opacity):
    means = np.asarray(p["means"], np.float32)
    opacity = np.asarray(p["opacity"], np.float32)
    keep = 1 / (1 + np.exp(-opacity)) >= min_opacity
    sh = np.asarray(p["sh"], np.float32)[keep]
    n = int(keep.sum())
    quats = np.asarray(p["quats"], np.float32)[keep]
    quats = quats / np.linalg.norm(quats, axis=1, keepdims=True)
    rest = np.transpose(sh[:, 1:, :], (0, 2, 1)).reshape(n, 45)  # channel-major
    cols = [means[keep], np.zeros((n, 3), np.float32), sh[:, 0, :], rest, opacity[keep][:, None],
            np.asarray(p["log_scales"], np.float32)[keep], quats]
    data = np.ascontiguousarray(np.concatenate(cols, 1).astype("<f4"))
    names = (["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{i}" for i in range(3)]
             + [f"f_rest_{i}" for i in range(45)] + ["opacity"] + [f"scale_{i}" for i in range(3)]
             + [f"rot_{i}" for i in range(4)])
    assert data.shape[1] == len(names)
    header = "ply\nformat binary_little_endian 1.0\n"
    header += "comment 3D Gaussians fitted by pointlens scripts/gaussians/train.py\n"
    header += f"element vertex {n}\n" + "".join(f"property float {k}\n" for k in names) + "end_header\n"
    tmp = Path(str(path) + ".part")
    with open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(data.tobytes())
    tmp.replace(path)
    return n


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--views", required=True, help="folder of vNN.json (pointlens --print-camera) + vNN.png")
    ap.add_argument("--splats", required=True, help="examples/export_splats output of the cloud")
    ap.add_argument("-o", "--out", required=True, help="the PLY to write")
    ap.add_argument("--gaussians", type=int, default=20000)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--max-seconds", type=float, default=1e9, help="stop (and write) after this long")
    ap.add_argument("--chunk", type=int, default=2048, help="pixels composited at once")
    ap.add_argument("--background", default="0,0,0", help="sRGB-encoded R,G,B of the views' background")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hold-out", type=int, default=4, help="every Nth view is not trained on (0: none)")
    a = ap.parse_args(argv)
    if a.max_seconds <= 0 or a.steps < 1 or a.gaussians < 1 or a.chunk < 1:
        raise SystemExit("--max-seconds, --steps, --gaussians and --chunk must be positive")
    background = jnp.asarray([float(v) for v in a.background.split(",")], jnp.float32)

    views = load_views(a.views)
    height, width, _ = views[0]["image"].shape
    held = [a.hold_out > 0 and i % a.hold_out == a.hold_out - 1 for i in range(len(views))]
    test = [v for v, h in zip(views, held) if h]
    train = [v for v, h in zip(views, held) if not h]
    try:
        splats = splat_scene.read_splats(a.splats)
    except ValueError as e:
        raise SystemExit(str(e))
    p = init_params(splats, a.gaussians, a.seed)
    extent = float(np.linalg.norm(np.ptp(splats[0], axis=0)))
    log(f"{len(train)} training views, {len(test)} held out, {width}x{height}; "
        f"{p['means'].shape[0]} Gaussians; extent {extent:.1f}; {jax.devices()[0]}")
    render = make_render(width, height, a.chunk)

    lrs = {"means": 1.6e-4 * extent, "log_scales": 5e-3, "quats": 1e-3, "opacity": 0.05, "sh": 2.5e-3}
    sh_rest_factor = 1 / 20

    def loss_fn(p, eye, w, f, target):
        img = render(p, eye, w, f, background)
        return jnp.mean(jnp.abs(img - target))

    @jax.jit
    def step(p, m, v, t, frac, eye, w, f, target):
        loss, grads = jax.value_and_grad(loss_fn)(p, eye, w, f, target)
        lr = dict(lrs)
        lr["means"] = lrs["means"] * (0.01 ** frac)
        new_p, new_m, new_v = {}, {}, {}
        for k in p:
            g = grads[k]
            new_m[k] = 0.9 * m[k] + 0.1 * g
            new_v[k] = 0.999 * v[k] + 0.001 * g * g
            mh = new_m[k] / (1 - 0.9 ** (t + 1))
            vh = new_v[k] / (1 - 0.999 ** (t + 1))
            upd = lr[k] * mh / (jnp.sqrt(vh) + 1e-15)
            if k == "sh":
                upd = upd.at[:, 1:, :].multiply(sh_rest_factor)
            new_p[k] = p[k] - upd
        return new_p, new_m, new_v, loss

    render_jit = jax.jit(render)

    def psnr_of(vs):
        out = []
        for v in vs:
            img = np.asarray(render_jit(p, v["eye"], v["w"], v["f"], background))
            mse = float(np.mean((np.clip(img, 0, 1) - v["image"]) ** 2))
            out.append(10 * math.log10(1 / max(mse, 1e-12)))
        return out

    m = {k: jnp.zeros_like(x) for k, x in p.items()}
    v = {k: jnp.zeros_like(x) for k, x in p.items()}
    rng = np.random.default_rng(a.seed)
    started = time.perf_counter()
    losses = []
    t = 0
    for t in range(a.steps):
        view = train[rng.integers(len(train))]
        # The schedule runs over the steps or the time allowed, whichever
        # ends first.
        frac = min(1.0, max(t / a.steps, (time.perf_counter() - started) / a.max_seconds))
        p, m, v, loss = step(p, m, v, jnp.float32(t), jnp.float32(frac), view["eye"], view["w"], view["f"],
                             view["image"])
        losses.append(float(loss))
        if t == 0:
            log(f"first step (compilation included) {time.perf_counter() - started:.1f} s")
        if (t + 1) % 100 == 0:
            log(f"step {t + 1}: L1 {np.mean(losses[-100:]):.4f}, {time.perf_counter() - started:.0f} s")
        if time.perf_counter() - started > a.max_seconds:
            log(f"stopping at step {t + 1}: --max-seconds reached")
            break
    steps_done = t + 1
    train_psnr = psnr_of(train)
    test_psnr = psnr_of(test) if test else []
    n = write_ply(a.out, p, min_opacity=1 / 255)
    summary = {"gaussians": n, "initial": int(p["means"].shape[0]), "steps": steps_done,
               "seconds": round(time.perf_counter() - started, 1), "width": width, "height": height,
               "train_views": len(train), "held_out_views": len(test),
               "train_psnr_mean": round(float(np.mean(train_psnr)), 2),
               "held_out_psnr_mean": round(float(np.mean(test_psnr)), 2) if test else None,
               "device": str(jax.devices()[0]), "final_l1": round(float(np.mean(losses[-100:])), 4)}
    log(json.dumps(summary))
    Path(str(a.out) + ".json").write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])

"""Self-test of aperture_sensor.py against docs/decisions/aperture-shape.md.

    ~/.cache/pointlens/venv-mitsuba/bin/python scripts/mitsuba/aperture_check.py [--spp N] [--save DIR] [--verbose]

Prints one table row per check and exits 1 if any fails (2 on a setup
error). Two to three and a half minutes on 2 cores (16 renders at 2048
spp with Mitsuba's llvm_ad_rgb variant, which needs libLLVM ≥ 19:
DRJIT_LIBLLVM_PATH, else the newest found under /usr/lib).
scripts/mitsuba/aperture_check.txt holds a run's output.

Three kinds of checks:

* plumbing: the aperture images the test writes (a star pointing up as an
  8-bit PNG and at half transmission as a 16-bit PNG, a ring as a
  one-channel EXR) read back exactly; the reader refuses what the document
  excludes; sensor_from_camera maps a --print-camera JSON; the rays of the
  round aperture equal thinlens's with the aperture sample ξ ↦ 1 − ξ
  (a cropped film, near/far clip, differentials);
* the sampler alone (no rendering): `sample_lens` of the sensor for 2²⁰
  lens samples, histogrammed on a 48×48 grid over the lens square, against
  the cell integrals of T(u)·C(u; p) of the document (numpy, 8×8 points a
  cell; the L1 distance against the multinomial noise of 2²⁰ samples);
  the share of samples where T·C = 0; the cat's eye's fallback share;
* renders: a 256×256 frame, fov_y 40°, focus S = 1, aperture radius R so
  that a highlight at depth 5 has CoC c = 2·R·f_px·|z − S|/(z·S) = 128 px
  (f_px = (H/2)/tan(fov_y/2)); the highlight a small emitting sphere whose
  pinhole image is a disk of radius 6 px (the bokeh is the aperture's shape
  blurred by that disk), `path` with max_depth 1, black background,
  `multijitter` 256 spp a pass. Measures: the bokeh's area as
  (sum of the image) / (its plateau, the mean over the pixels where the
  predicted image is flat), exact under the emitter's blur; second moments
  (the emitter's disk, variance r²/4 an axis, subtracted); extents of the
  half-plateau mask; and "dist", the L1 distance of two images each
  smoothed (Gaussian σ = 1.5 px) and normalised to sum 1 (0 = equal,
  2 = disjoint; two renders of one distribution with different seeds give
  the noise floor, printed, and the thresholds are multiples of it).

The document's prediction of a render: per pixel p, the mean over 2×2
points p′ of the pixel and the points o of the emitter's image disk of
T(u)·C(u; p) with u = 2(p′ − q − o)/(sign·c), over ∫T·C(·; p) (96×96
points), times the area in u of the lens positions whose rays through the
pixel's point F of the focal plane hit the sphere, π·S²·ρ²·|E − F| /
(|E.z − F.z|³·R²) (the oblique cone from F: π(2r/c)² near the axis, 3 %
more for the highlight in front of the focus plane, 8 % more for the one
near the corner). Its energy against the render's checks the absolute
level: no darkening, the per-pixel normalisation of the cat's eye (whose
highlight's energy is not the round one's: each pixel divides by its own
∫T·C).
"""

import argparse
import glob
import math
import os
import re
import sys
import time


def find_llvm():
    best, best_v = None, 0
    for f in glob.glob("/usr/lib/*/libLLVM-[0-9]*.so*") + glob.glob("/usr/lib/*/libLLVM.so.[0-9]*") \
            + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        m = re.match(r"^libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(f))
        if m and int(m.group(1)) >= 19 and int(m.group(1)) > best_v:
            best, best_v = f, int(m.group(1))
    return best


if "DRJIT_LIBLLVM_PATH" not in os.environ:
    _llvm = find_llvm()
    if _llvm:
        os.environ["DRJIT_LIBLLVM_PATH"] = _llvm

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import aperture_sensor as ap  # noqa: E402

W = H = 256
FOVY = 40.0
FOCUS = 1.0
Z_BEHIND = 5.0
COC = 128.0
R_EMIT_PX = 6.0
F_PX = (H / 2.0) / math.tan(math.radians(FOVY) / 2.0)
# |z − S|/(z·S) at z = 5: 0.8; R from c = 2·R·f_px·0.8.
RADIUS = COC / (2.0 * F_PX * abs(Z_BEHIND - FOCUS) / (Z_BEHIND * FOCUS))
# In front of the focus plane with the same CoC: (S − z)/(z·S) = 0.8.
Z_FRONT = FOCUS / (1.0 + abs(Z_BEHIND - FOCUS) / Z_BEHIND)


def coc_px(z):
    return 2.0 * RADIUS * F_PX * abs(z - FOCUS) / (z * FOCUS)


class Checker:
    def __init__(self, args):
        import drjit as dr
        import mitsuba as mi

        self.mi, self.dr, self.args = mi, dr, args
        self.rows = []
        self.renders = 0
        self.render_s = 0.0

    def log(self, msg):
        if self.args.verbose:
            print(f"[aperture_check] {msg}", file=sys.stderr, flush=True)

    def row(self, check, measured, expected, ok):
        self.rows.append((check, measured, expected, bool(ok)))
        self.log(f"{'ok  ' if ok else 'FAIL'} {check}: {measured} (want {expected})")

    # -- scenes ----------------------------------------------------------------
    def sensor_dict(self, aperture, kind=ap.NAME):
        mi = self.mi
        s = {
            "type": kind,
            "fov": FOVY,
            "fov_axis": "y",
            "aperture_radius": RADIUS,
            "focus_distance": FOCUS,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32"},
            "sampler": {"type": "multijitter", "sample_count": 256},
        }
        s.update(aperture)
        return s

    @staticmethod
    def emitter_at(qx, qy, z):
        """World centre and radius of the sphere whose pinhole image is
        centred at pixel (qx, qy) with radius R_EMIT_PX. look_at(0 → +z,
        up +y): camera +x = world +x is the image's left, so pixel
        x = W/2 − f·X/z and y = H/2 − f·Y/z."""
        x = -(qx - W / 2.0) * z / F_PX
        y = -(qy - H / 2.0) * z / F_PX
        rho = R_EMIT_PX * z / math.hypot(F_PX, R_EMIT_PX)
        return [x, y, z], rho

    def render(self, aperture, z=Z_BEHIND, q=(W / 2.0, H / 2.0), kind=ap.NAME, seed0=0):
        mi = self.mi
        centre, rho = self.emitter_at(q[0], q[1], z)
        scene = mi.load_dict({
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 1},
            "sensor": self.sensor_dict(aperture, kind),
            "light": {"type": "sphere", "center": centre, "radius": rho,
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}},
        })
        started = time.perf_counter()
        passes = max(1, self.args.spp // 256)
        img = np.zeros((H, W), np.float64)
        for k in range(passes):
            out = mi.render(scene, spp=256, seed=seed0 * 1000 + k)
            img += np.array(out, dtype=np.float64)[..., 0]
        img /= passes
        self.renders += 1
        self.render_s += time.perf_counter() - started
        self.log(f"rendered {aperture} z={z:g} q={q} ({time.perf_counter() - started:.1f} s)")
        if self.args.save:
            os.makedirs(self.args.save, exist_ok=True)
            name = "_".join(f"{k}-{v}" for k, v in aperture.items() if k != "aperture_image") or "round"
            if "aperture_image" in aperture:
                name += "_" + os.path.basename(aperture["aperture_image"]).replace(".", "-")
            np.save(os.path.join(self.args.save, f"{kind}_{name}_z{z:g}_q{q[0]:g}-{q[1]:g}_s{seed0}.npy"), img)
        return img

    # -- predictions -------------------------------------------------------------
    def predict(self, shape, z=Z_BEHIND, q=(W / 2.0, H / 2.0)):
        """The document's image of the emitter: per pixel p, the mean over
        2×2 points p′ of the pixel and the emitter's disk points o of
        T(u)·C(u; p) with u = 2(p′ − q − o)/(sign·c), over ∫T·C(·; p)."""
        c = coc_px(z)
        sign = 1.0 if z > FOCUS else -1.0
        g = np.arange(-R_EMIT_PX, R_EMIT_PX + 1e-9, 1.0)
        ox, oy = np.meshgrid(g, g)
        keep = ox ** 2 + oy ** 2 <= R_EMIT_PX ** 2
        offs = np.stack([ox[keep], oy[keep]], axis=1)
        sub = np.array([[-0.25, -0.25], [0.25, -0.25], [-0.25, 0.25], [0.25, 0.25]])
        pts = (offs[:, None, :] + sub[None, :, :]).reshape(-1, 2)
        reach = c / 2.0 + R_EMIT_PX + 2.0
        x0, x1 = max(0, int(q[0] - reach)), min(W, int(q[0] + reach) + 1)
        y0, y1 = max(0, int(q[1] - reach)), min(H, int(q[1] + reach) + 1)
        img = np.zeros((H, W))
        ys, xs = np.mgrid[y0:y1, x0:x1]
        px = xs.ravel() + 0.5
        py = ys.ravel() + 0.5
        s = shape.cat_eye
        norm_area = self.cat_norm(shape, px, py) if s > 0 else np.full(px.shape, shape.area_u())
        out = np.zeros(px.shape)
        step = 2048
        for i in range(0, len(px), step):
            ppx, ppy = px[i:i + step, None], py[i:i + step, None]
            ux = 2.0 * (ppx - q[0] - pts[None, :, 0]) / (sign * c)
            uy = 2.0 * (ppy - q[1] - pts[None, :, 1]) / (sign * c)
            t = shape.transmission(np.stack([ux, uy], axis=-1))
            if s > 0:
                cx, cy = shape.cat_eye_centre(ppx, ppy, W, H, s)
                t = t * ((ux - cx) ** 2 + (uy - cy) ** 2 <= 1.0)
            out[i:i + step] = t.mean(axis=1) / norm_area[i:i + step]
        # Absolute, for an emitter of radiance 1: times the area, in u, of the
        # lens positions whose rays through the pixel's point F of the focal
        # plane hit the sphere (centre E, radius ρ; camera space = world
        # here): the cone from F tangent to the sphere cut by the lens plane,
        # π·S²·ρ²·|E − F| / (|E.z − F.z|³·R²) for a small sphere (near the
        # axis π(2r/c)²; an oblique cone cuts a larger ellipse).
        (ex, ey, ez), rho = self.emitter_at(q[0], q[1], z)
        fx = -(px - W / 2.0) / F_PX * FOCUS
        fy = -(py - H / 2.0) / F_PX * FOCUS
        dist_ef = np.sqrt((ex - fx) ** 2 + (ey - fy) ** 2 + (ez - FOCUS) ** 2)
        area = math.pi * FOCUS ** 2 * rho ** 2 * dist_ef / (abs(ez - FOCUS) ** 3 * RADIUS ** 2)
        img[y0:y1, x0:x1] = (out * area).reshape(ys.shape)
        return img

    @staticmethod
    def cat_norm(shape, px, py, n=96):
        """∫T(u)·C(u; p) du per pixel centre (n×n points over the lens
        square), from the document."""
        g = -1.0 + (np.arange(n) + 0.5) * 2.0 / n
        ux, uy = np.meshgrid(g, g)
        t = shape.transmission(np.stack([ux, uy], axis=-1)).ravel()
        keep = t > 0
        ux, uy, t = ux.ravel()[keep], uy.ravel()[keep], t[keep]
        out = np.empty(px.shape)
        cx, cy = shape.cat_eye_centre(px, py, W, H, shape.cat_eye)
        for i in range(0, len(px), 1024):
            inside = (ux[None, :] - cx[i:i + 1024, None]) ** 2 + (uy[None, :] - cy[i:i + 1024, None]) ** 2 <= 1.0
            out[i:i + 1024] = (inside * t[None, :]).sum(axis=1) * (2.0 / n) ** 2
        return np.maximum(out, 1e-12)

    # -- measures ----------------------------------------------------------------
    @staticmethod
    def smooth(img, sigma=1.5):
        r = int(math.ceil(3 * sigma))
        k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
        k /= k.sum()
        out = np.apply_along_axis(lambda v: np.convolve(v, k, mode="same"), 0, img)
        return np.apply_along_axis(lambda v: np.convolve(v, k, mode="same"), 1, out)

    def dist(self, a, b):
        a, b = self.smooth(a), self.smooth(b)
        return float(np.abs(a / a.sum() - b / b.sum()).sum())

    def vs_doc(self, label, img, pred):
        """One row: the dist of a render to the document's prediction, and
        the ratio of their energies (absolute: per-pixel normalisation,
        no darkening)."""
        floor = self.noise_floor
        d = self.dist(img, pred)
        e = float(img.sum() / pred.sum())
        self.row(f"{label}: dist to the document's prediction; energy ratio", f"{d:.4f}; {e:.4f}",
                 f"< {3 * floor:.4f}; 1 ± 0.015", d < 3 * floor and abs(e - 1) < 0.015)

    @staticmethod
    def plateau_mask(pred):
        return pred >= 0.999 * pred.max()

    def area_px(self, img, pred):
        plateau = img[self.plateau_mask(pred)].mean()
        return float(img.sum() / plateau)

    @staticmethod
    def moments(img):
        ys, xs = np.mgrid[0:img.shape[0], 0:img.shape[1]]
        xs, ys = xs + 0.5, ys + 0.5
        m = img.sum()
        cx, cy = (img * xs).sum() / m, (img * ys).sum() / m
        sxx = (img * (xs - cx) ** 2).sum() / m
        syy = (img * (ys - cy) ** 2).sum() / m
        sxy = (img * (xs - cx) * (ys - cy)).sum() / m
        return cx, cy, np.array([[sxx, sxy], [sxy, syy]])

    def mask(self, img, pred):
        plateau = img[self.plateau_mask(pred)].mean()
        return self.smooth(img) > 0.5 * plateau

    @staticmethod
    def extents(mask, cx, cy):
        rows = np.flatnonzero(mask.any(axis=1))
        cols = np.flatnonzero(mask.any(axis=0))
        top, bottom = cy - rows[0], rows[-1] + 1 - cy
        left, right = cx - cols[0], cols[-1] + 1 - cx
        return top, bottom, left, right

    # -- checks ------------------------------------------------------------------
    def sampler_checks(self):
        mi, dr = self.mi, self.dr
        n = 1 << 20
        rng = np.random.default_rng(7)
        cases = [
            ("7 blades, C 0.4, 20°, A 1.6", {"aperture_blades": 7, "blade_curvature": 0.4,
                                             "aperture_rotation_deg": 20.0, "anamorphic_ratio": 1.6}, None),
            ("3 blades, A 0.5", {"aperture_blades": 3, "anamorphic_ratio": 0.5}, None),
            ("star image, 15°", {"aperture_image": self.star_png, "aperture_rotation_deg": 15.0}, None),
            ("round, S 0.8, corner pixel", {"cat_eye": 0.8}, (250, 6)),
            # d at screen angle 210°: the lens is seen near the corner at 30°.
            ("6 blades, S 1, pixel (4, 199)", {"aperture_blades": 6, "cat_eye": 1.0}, (4, 199)),
            ("star image, S 1, pixel (230, 40)", {"aperture_image": self.star_png, "cat_eye": 1.0}, (230, 40)),
            # A cropped film: the frame's pixel is the crop's plus its offset.
            ("5 blades, S 0.9, pixel (20, 230) of a crop at (10, 200)", {"aperture_blades": 5, "cat_eye": 0.9},
             (20, 230), (10, 200, 40, 50)),
        ]
        grid = 48
        for label, aperture, pixel, *crop in cases:
            sd = self.sensor_dict(aperture)
            pix = pixel or (W // 2, H // 2)
            if crop:
                ox, oy, cw, ch = crop[0]
                sd["film"].update(crop_offset_x=ox, crop_offset_y=oy, crop_width=cw, crop_height=ch)
                pos = mi.Point2f((pix[0] - ox + 0.5) / cw, (pix[1] - oy + 0.5) / ch)
            else:
                pos = mi.Point2f((pix[0] + 0.5) / W, (pix[1] + 0.5) / H)
            sensor = mi.load_dict(sd)
            shape = sensor.shape
            xi = mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32))
            u, fell = sensor.sample_lens(dr.zeros(mi.Point2f, n) + pos, xi)
            u = np.array(u, dtype=np.float64)
            u = u.T if u.shape[0] == 2 else u
            fell = np.array(fell)
            hist, _, _ = np.histogram2d(u[:, 1], u[:, 0], bins=grid, range=[[-1, 1], [-1, 1]])
            # Expected: T·C integrated over each cell (8×8 points).
            k = 8
            g = -1.0 + (np.arange(grid * k) + 0.5) * 2.0 / (grid * k)
            ux, uy = np.meshgrid(g, g)
            t = shape.transmission(np.stack([ux, uy], axis=-1))
            cpx, cpy = pix[0] + 0.5, pix[1] + 0.5
            if shape.cat_eye > 0:
                cx, cy = shape.cat_eye_centre(cpx, cpy, W, H, shape.cat_eye)
                t = t * ((ux - cx) ** 2 + (uy - cy) ** 2 <= 1.0)
            want = t.reshape(grid, k, grid, k).sum(axis=(1, 3))
            if want.sum() <= 0.0:
                self.row(f"sampler {label}: T·C", "empty (the pixel sees no lens)", "not empty", False)
                continue
            want /= want.sum()
            got = hist / hist.sum()
            l1 = float(np.abs(got - want).sum())
            # The noise of 2²⁰ multinomial samples over the lit cells.
            lit = np.count_nonzero(want)
            noise = math.sqrt(2.0 / math.pi) * math.sqrt(lit / n)
            tu = shape.transmission(u)
            if shape.cat_eye > 0:
                cx, cy = shape.cat_eye_centre(cpx, cpy, W, H, shape.cat_eye)
                tu = tu * ((u[:, 0] - cx) ** 2 + (u[:, 1] - cy) ** 2 <= 1.0 + 1e-6)
            outside = float(np.mean(tu == 0.0))
            self.row(f"sampler {label}: histogram L1 vs T·C",
                     f"{l1:.4f} (noise ≈ {noise:.4f})", f"< {max(3 * noise, 0.01):.4f}", l1 < max(3 * noise, 0.01))
            self.row(f"sampler {label}: samples where T·C = 0 / fallbacks",
                     f"{outside:.2e} / {fell.mean():.2e}", "< 1e-3 / < 1e-3", outside < 1e-3 and fell.mean() < 1e-3)

    def render_checks(self):
        shape_of = lambda a: ap.ApertureShape(  # noqa: E731
            blades=a.get("aperture_blades", 0), rotation_deg=a.get("aperture_rotation_deg", 0.0),
            curvature=a.get("blade_curvature", 0.0), ratio=a.get("anamorphic_ratio", 1.0),
            image=a.get("aperture_image"), cat_eye=a.get("cat_eye", 0.0))
        rc = COC / 2.0
        centre = (W / 2.0, H / 2.0)

        # (0) Round, no cat's eye: the same lens distribution as thinlens.
        round_img = self.render({})
        round_img2 = self.render({}, seed0=1)
        thin = self.render({}, kind="thinlens", seed0=2)
        floor = self.dist(round_img, round_img2)
        self.noise_floor = floor
        d = self.dist(round_img, thin)
        ratio = round_img.sum() / thin.sum()
        self.row("(0) round = Mitsuba thinlens: dist; energy ratio",
                 f"{d:.4f} (seed-to-seed {floor:.4f}); {ratio:.4f}",
                 f"dist < {2 * floor:.4f}; 1 ± 0.01", d < 2 * floor and abs(ratio - 1) < 0.01)

        # (a) Round: area π(c/2)².
        pred = self.predict(shape_of({}))
        area = self.area_px(round_img, pred)
        want = math.pi * rc * rc
        self.row("(a) round: bokeh area px² (c = 128 px)", f"{area:.1f}", f"π(c/2)² = {want:.1f} ± 3%",
                 abs(area / want - 1) < 0.03)
        self.vs_doc("(a) round", round_img, pred)

        # (b) Six blades: the hexagon's area; 30° = 90°.
        six = {"aperture_blades": 6}
        img6 = self.render(six)
        pred6 = self.predict(shape_of(six))
        area = self.area_px(img6, pred6)
        want = 3.0 * math.sqrt(3.0) / 2.0 * rc * rc
        self.row("(b) 6 blades: bokeh area px²", f"{area:.1f}", f"3√3/2·(c/2)² = {want:.1f} ± 3%",
                 abs(area / want - 1) < 0.03)
        self.vs_doc("(b) 6 blades", img6, pred6)
        img6_30 = self.render({"aperture_blades": 6, "aperture_rotation_deg": 30.0})
        img6_90 = self.render({"aperture_blades": 6, "aperture_rotation_deg": 90.0})
        d_same = self.dist(img6_30, img6_90)
        d_diff = self.dist(img6_30, img6)
        self.row("(b) 6 blades 30° vs 90°: dist (vs 0°, a different shape)",
                 f"{d_same:.4f} (vs 0°: {d_diff:.4f})", f"< {2 * floor:.4f} (vs 0°: > {4 * floor:.4f})",
                 d_same < 2 * floor and d_diff > 4 * floor)

        # (b) Five blades: 36° = the unrotated flipped vertically, ≠ unrotated.
        five = {"aperture_blades": 5}
        img5 = self.render(five)
        img5_36 = self.render({"aperture_blades": 5, "aperture_rotation_deg": 36.0})
        d_flip = self.dist(img5_36, img5[::-1, :])
        d_plain = self.dist(img5_36, img5)
        self.row("(b) 5 blades 36° vs 0° flipped vertically (vs 0° as is)",
                 f"{d_flip:.4f} (as is: {d_plain:.4f})", f"< {2 * floor:.4f} (as is: > {4 * floor:.4f})",
                 d_flip < 2 * floor and d_plain > 4 * floor)
        pred5 = self.predict(shape_of(five))
        m = self.mask(img5, pred5)
        rows = np.flatnonzero(m.any(axis=1))
        top = rows[0]
        xs = np.flatnonzero(m[top]) + 0.5
        cx, cy, _ = self.moments(img5)
        t, b, _, _ = self.extents(m, centre[0], centre[1])
        self.row("(b) 5 blades 0°: topmost lit row's centroid x − bokeh centre x (px); its width",
                 f"{xs.mean() - cx:+.2f}; {len(xs)} px", "|·| < 1; < 10 px (a corner)",
                 abs(xs.mean() - cx) < 1.0 and len(xs) < 10)
        want_tb = 1.0 / math.cos(math.pi / 5)
        self.row("(b) 5 blades 0°: top / bottom extent from q (corner up)", f"{t / b:.3f}",
                 f"> 1.1 (sharp: 1/cos 36° = {want_tb:.3f})", t / b > 1.1)
        img5_90 = self.render({"aperture_blades": 5, "aperture_rotation_deg": 90.0})
        m = self.mask(img5_90, self.predict(shape_of({"aperture_blades": 5, "aperture_rotation_deg": 90.0})))
        _, _, left, right = self.extents(m, centre[0], centre[1])
        col = np.flatnonzero(m.any(axis=0))[0]
        ys = np.flatnonzero(m[:, col]) + 0.5
        self.row("(b) 5 blades 90°: left / right extent; leftmost column's centroid y − q.y",
                 f"{left / right:.3f}; {ys.mean() - centre[1]:+.2f}", "> 1.1 (corner left); |·| < 1",
                 left / right > 1.1 and abs(ys.mean() - centre[1]) < 1.0)

        # (c) Anamorphic A = 2: height / width = 2 by second moments.
        ana = {"anamorphic_ratio": 2.0}
        img_a = self.render(ana)
        _, _, cov = self.moments(img_a)
        blur = R_EMIT_PX ** 2 / 4.0
        hw = math.sqrt((cov[1, 1] - blur) / (cov[0, 0] - blur))
        self.row("(c) anamorphic 2: height / width (second moments, emitter's disk removed)",
                 f"{hw:.3f}", "2 ± 3%", abs(hw / 2 - 1) < 0.03)
        pred_a = self.predict(shape_of(ana))
        self.vs_doc("(c) anamorphic 2", img_a, pred_a)
        area = self.area_px(img_a, pred_a)
        want = math.pi * rc * rc / 2.0
        self.row("(c) anamorphic 2: bokeh area px²", f"{area:.1f}", f"π(c/2)²/2 = {want:.1f} ± 3%",
                 abs(area / want - 1) < 0.03)

        # (d) In front of the focus plane: the 5 blades turned by 180°.
        assert abs(coc_px(Z_FRONT) - COC) < 1e-9
        img5_front = self.render(five, z=Z_FRONT)
        d_turn = self.dist(img5_front[::-1, ::-1], img5)
        d_plain = self.dist(img5_front, img5)
        self.row("(d) 5 blades in front of focus, turned 180°, vs behind (vs as is)",
                 f"{d_turn:.4f} (as is: {d_plain:.4f})", f"< {2 * floor:.4f} (as is: > {4 * floor:.4f})",
                 d_turn < 2 * floor and d_plain > 4 * floor)
        self.vs_doc("(d) 5 blades in front", img5_front, self.predict(shape_of(five), z=Z_FRONT))

        # (e) Cat's eye S = 0.8.
        cat = {"cat_eye": 0.8}
        sh = shape_of(cat)
        img_c = self.render(cat)
        pred_c = self.predict(sh)
        _, _, cov = self.moments(img_c)
        ev = np.linalg.eigvalsh(cov)
        iso = math.sqrt(ev[1] / ev[0])
        self.row("(e) cat's eye 0.8, highlight at the centre: major / minor axis", f"{iso:.3f}", "1 ± 0.03",
                 abs(iso - 1) < 0.03)
        # The pixel at distance r from q sees u = 2r/c outward and the second
        # circle at −2S·r/|half| inward: lit while r ≤ 1/(2/c + 2S/|half|).
        r_pred = 1.0 / (2.0 / COC + 2.0 * 0.8 / math.hypot(W / 2.0, H / 2.0))
        m = self.mask(img_c, pred_c)
        r_meas = math.sqrt(m.sum() / math.pi)
        self.row("(e) cat's eye 0.8, centre: radius of the lit disk px", f"{r_meas:.2f}",
                 f"1/(2/c + 2S/|(W/2,H/2)|) = {r_pred:.2f} ± 1.5", abs(r_meas - r_pred) < 1.5)
        self.vs_doc("(e) cat's eye 0.8, centre", img_c, pred_c)
        corner_q = (224.0, 224.0)
        img_k = self.render(cat, q=corner_q)
        pred_k = self.predict(sh, q=corner_q)
        cx, cy, cov = self.moments(img_k)
        pcx, pcy, pcov = self.moments(pred_k)
        ev, vec = np.linalg.eigh(cov)
        major = vec[:, 1]
        to_centre = np.array([W / 2.0 - cx, H / 2.0 - cy])
        to_centre /= np.linalg.norm(to_centre)
        angle = math.degrees(math.acos(min(1.0, abs(float(major @ to_centre)))))
        elong = math.sqrt(ev[1] / ev[0])
        pev = np.linalg.eigvalsh(pcov)
        pelong = math.sqrt(pev[1] / pev[0])
        self.row("(e) cat's eye 0.8, highlight at (224, 224): long axis to the direction to the centre",
                 f"{angle:.1f}°", "90° ± 5°", abs(angle - 90.0) < 5.0)
        self.row("(e) cat's eye 0.8, corner: major / minor axis (the document's)", f"{elong:.3f}",
                 f"{pelong:.3f} ± 3%, > 1.25 (a lens shape)", abs(elong / pelong - 1) < 0.03 and elong > 1.25)
        self.row("(e) cat's eye 0.8, corner: centroid − the document's (px)",
                 f"{cx - pcx:+.2f}, {cy - pcy:+.2f}", "|·| < 1", abs(cx - pcx) < 1 and abs(cy - pcy) < 1)
        self.vs_doc("(e) cat's eye 0.8, corner", img_k, pred_k)

        # (f) An aperture image: area ∝ the mean transmission in the circle.
        star = {"aperture_image": self.star_png}
        sh = shape_of(star)
        img_s = self.render(star)
        pred_s = self.predict(sh)
        area = self.area_px(img_s, pred_s)
        mean_t = sh.mean_transmission_in_circle()
        want = mean_t * math.pi * rc * rc
        self.row("(f) star PNG (8 bit): bokeh area px²", f"{area:.1f}",
                 f"mean T in circle {mean_t:.4f} × π(c/2)² = {want:.1f} ± 3%", abs(area / want - 1) < 0.03)
        self.vs_doc("(f) star PNG", img_s, pred_s)
        d_flip = self.dist(img_s, pred_s[::-1, :])
        self.row("(f) star PNG: dist to the document's prediction flipped vertically (row 0 at the top)",
                 f"{d_flip:.4f}", f"> {4 * floor:.4f}", d_flip > 4 * floor)
        ring = {"aperture_image": self.ring_exr}
        sh = shape_of(ring)
        img_r = self.render(ring)
        pred_r = self.predict(sh)
        self.vs_doc("(f) ring EXR", img_r, pred_r)
        area = self.area_px(img_r, pred_r)
        mean_t = sh.mean_transmission_in_circle()
        want = mean_t * math.pi * rc * rc
        self.row("(f) ring EXR (one channel, float): bokeh area px²", f"{area:.1f}",
                 f"mean T in circle {mean_t:.4f} × π(c/2)² = {want:.1f} ± 3%", abs(area / want - 1) < 0.03)
        half = {"aperture_image": self.star_half_png}
        img_h = self.render(half, seed0=3)
        d = self.dist(img_h, img_s)
        ratio = img_h.sum() / img_s.sum()
        self.row("(f) star at half transmission (16-bit PNG) vs star: dist; energy ratio (no darkening)",
                 f"{d:.4f}; {ratio:.4f}", f"< {2 * floor:.4f}; 1 ± 0.01", d < 2 * floor and abs(ratio - 1) < 0.01)

    def write_images(self, tmp):
        """The test's aperture images: a five-pointed star pointing up (8-bit
        PNG, and at half transmission as a 16-bit PNG) and a ring (EXR, one
        float channel); checks that they read back exactly."""
        mi = self.mi
        n = 200
        ys, xs = np.mgrid[0:n, 0:n]
        wx = -1.0 + 2.0 * (xs + 0.5) / n
        wy = -1.0 + 2.0 * (ys + 0.5) / n
        # Star: radius between 0.4 (inner corners) and 0.95 (points), a
        # point at the top (screen angle 90°).
        phi = np.arctan2(-wy, wx)
        r = np.hypot(wx, wy)
        sector = 2 * np.pi / 5
        t = np.abs(np.mod(phi - np.pi / 2 + sector / 2, sector) - sector / 2) / (sector / 2)
        star = (r <= 0.95 + (0.4 - 0.95) * t).astype(np.float64)
        ring = ((r >= 0.45) & (r <= 0.85)).astype(np.float32)
        self.star_png = os.path.join(tmp, "star.png")
        self.star_half_png = os.path.join(tmp, "star_half16.png")
        self.ring_exr = os.path.join(tmp, "ring.exr")
        mi.Bitmap((star * 255).astype(np.uint8)[:, :, None], pixel_format=mi.Bitmap.PixelFormat.Y).write(self.star_png)
        mi.Bitmap((star * 32768).astype(np.uint16)[:, :, None],
                  pixel_format=mi.Bitmap.PixelFormat.Y).write(self.star_half_png)
        mi.Bitmap(ring[:, :, None], pixel_format=mi.Bitmap.PixelFormat.Y).write(self.ring_exr)
        ok8 = np.array_equal(ap.read_aperture_image(self.star_png), star)
        ok16 = np.allclose(ap.read_aperture_image(self.star_half_png), star * 32768 / 65535, atol=0, rtol=0)
        okx = np.array_equal(ap.read_aperture_image(self.ring_exr), ring.astype(np.float64))
        self.row("aperture images read back (PNG 8 bit, PNG 16 bit, EXR)", f"{ok8}, {ok16}, {okx}",
                 "True, True, True", ok8 and ok16 and okx)

    def camera_checks(self, tmp):
        """sensor_from_camera, the image reader's refusals, and the rays
        against thinlens's."""
        import json

        mi, dr = self.mi, self.dr
        cam = {"width": 64, "height": 48, "eye": [1.0, 2.0, 3.0], "target": [1.0, 2.0, 10.0], "up": [0, 1, 0],
               "fovy_deg": 40.0, "aperture_radius": 0.1, "focus_distance": 2.5, "aperture_blades": 7,
               "aperture_rotation_deg": 10.0, "blade_curvature": 0.3, "anamorphic_ratio": 1.5, "cat_eye": 0.4}
        sensor = mi.load_dict(ap.sensor_from_camera(json.dumps(cam)))
        sh = sensor.shape
        want_xfov = math.degrees(2 * math.atan(math.tan(math.radians(20.0)) * 64 / 48))
        got = (sh.blades, sh.rotation_deg, round(sh.curvature, 6), sh.ratio, round(sh.cat_eye, 6),
               sensor.aperture_radius, sensor.focus_distance, sensor.film_size)
        want = (7, 10.0, 0.3, 1.5, 0.4, 0.1, 2.5, (64, 48))
        ok = got == want and abs(sensor.x_fov - want_xfov) < 1e-9
        plain = dict(cam, aperture_blades=None, aperture_rotation_deg=None, blade_curvature=None)
        for k in ("anamorphic_ratio", "cat_eye"):
            plain.pop(k)
        sh2 = mi.load_dict(ap.sensor_from_camera(plain)).shape
        ok2 = (sh2.blades, sh2.rotation_deg, sh2.curvature, sh2.ratio, sh2.cat_eye, sh2.image) == (0, 0, 0, 1, 0, None)
        pin = ap.sensor_from_camera(dict(cam, aperture_radius=0.0))["type"] == "perspective"
        rel = ap.sensor_from_camera(dict(cam, aperture_blades=None, aperture_image="star.png"), base_dir=tmp)
        ok3 = mi.load_dict(rel).shape.image is not None
        self.row("sensor_from_camera: fields; absent/null = defaults; R 0 = perspective; relative image",
                 f"{ok}, {ok2}, {pin}, {ok3}", "True, True, True, True", ok and ok2 and pin and ok3)

        # Refusals of the reader: RGB PNG, non-grey EXR, NaN.
        refused = []
        bad = [("rgb.png", np.zeros((4, 4, 3), np.uint8), mi.Bitmap.PixelFormat.RGB),
               ("color.exr", np.dstack([np.ones((4, 4)), np.zeros((4, 4)), np.zeros((4, 4))]).astype(np.float32),
                mi.Bitmap.PixelFormat.RGB),
               ("nan.exr", np.full((4, 4, 1), np.nan, np.float32), mi.Bitmap.PixelFormat.Y)]
        for name, arr, fmt in bad:
            path = os.path.join(tmp, name)
            mi.Bitmap(arr, pixel_format=fmt).write(path)
            try:
                ap.read_aperture_image(path)
                refused.append(False)
            except ValueError:
                refused.append(True)
        grey = os.path.join(tmp, "grey.exr")
        mi.Bitmap(np.dstack([np.full((4, 4), 0.25)] * 3).astype(np.float32),
                  pixel_format=mi.Bitmap.PixelFormat.RGB).write(grey)
        ok_grey = np.array_equal(ap.read_aperture_image(grey), np.full((4, 4), 0.25))
        self.row("image reader: refuses RGB PNG, non-grey EXR, NaN; reads a grey RGB EXR",
                 ", ".join(map(str, refused + [ok_grey])), "True, True, True, True", all(refused) and ok_grey)

        # Rays: the round aperture without cat's eye is thinlens with the
        # aperture sample ξ ↦ 1 − ξ (a = R·(−u), the concentric map odd).
        base = {"type": "thinlens", "fov": 40.0, "fov_axis": "y", "aperture_radius": 0.3, "focus_distance": 2.5,
                "near_clip": 0.05, "far_clip": 500.0,
                "to_world": mi.ScalarTransform4f().look_at(origin=[1, 2, 3], target=[2, 1, 9], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 96, "height": 64, "crop_offset_x": 10, "crop_offset_y": 6,
                         "crop_width": 50, "crop_height": 40}}
        thin = mi.load_dict(base)
        mine = mi.load_dict(dict(base, type=ap.NAME))
        n = 4096
        rng = np.random.default_rng(3)
        pos = mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32))
        xs = rng.random((2, n)).astype(np.float32)
        xi = mi.Point2f(xs[0], xs[1])
        xi_flip = mi.Point2f(1.0 - xs[0], 1.0 - xs[1])
        r1, _ = thin.sample_ray_differential(0.0, 0.5, pos, xi_flip)
        r2, w2 = mine.sample_ray_differential(0.0, 0.5, pos, xi)
        worst = 0.0
        for a, b in [(r1.o, r2.o), (r1.d, r2.d), (r1.d_x, r2.d_x), (r1.d_y, r2.d_y)]:
            worst = max(worst, float(np.abs(np.array(a) - np.array(b)).max()))
        dmax = float(np.abs(np.array(r1.maxt) / np.array(r2.maxt) - 1).max())
        wmin = float(np.array(w2).min())
        self.row("rays of the round aperture = thinlens's (ξ ↦ 1 − ξ), cropped film: max |Δo, Δd, Δd_x, Δd_y|; "
                 "maxt rel.; weight",
                 f"{worst:.1e}; {dmax:.1e}; {wmin:g}", "< 1e-5; < 1e-5; 1", worst < 1e-5 and dmax < 1e-5 and wmin == 1)

    def table(self):
        w0 = max(len(r[0]) for r in self.rows)
        w1 = max(len(r[1]) for r in self.rows)
        lines = [f"{'check':<{w0}} | {'measured':<{w1}} | expected | result",
                 f"{'-' * w0}-|-{'-' * w1}-|----------|-------"]
        for check, measured, expected, ok in self.rows:
            lines.append(f"{check:<{w0}} | {measured:<{w1}} | {expected} | {'ok' if ok else 'FAIL'}")
        return "\n".join(lines)


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--variant", default="llvm_ad_rgb")
    p.add_argument("--spp", type=int, default=2048, help="samples per pixel of each render (multiple of 256)")
    p.add_argument("--save", help="save every render as .npy into this folder")
    p.add_argument("--verbose", action="store_true", help="progress on stderr")
    args = p.parse_args(argv)
    import tempfile

    import mitsuba as mi

    if args.variant not in mi.variants():
        print(f"aperture_check: variant {args.variant} not in {mi.variants()}", file=sys.stderr)
        return 2
    mi.set_variant(args.variant)
    mi.set_log_level(mi.LogLevel.Warn)
    ap.register()
    started = time.perf_counter()
    chk = Checker(args)
    with tempfile.TemporaryDirectory(prefix="aperture_check.") as tmp:
        chk.write_images(tmp)
        chk.camera_checks(tmp)
        chk.sampler_checks()
        chk.render_checks()
    elapsed = time.perf_counter() - started
    import drjit as dr

    print(f"aperture_check: Mitsuba {mi.__version__} (Dr.Jit {dr.__version__}), variant {args.variant}, "
          f"{os.cpu_count()} cores; {W}×{H}, fov_y {FOVY}°, S = {FOCUS}, R = {RADIUS:.5f}, "
          f"c = {COC:g} px at z = {Z_BEHIND:g} and z = {Z_FRONT:.4f}, emitter disk radius {R_EMIT_PX:g} px, "
          f"{args.spp} spp (multijitter); {chk.renders} renders in {chk.render_s:.1f} s, {elapsed:.1f} s in all")
    print(chk.table())
    failed = [r for r in chk.rows if not r[3]]
    print(f"aperture_check: {len(chk.rows) - len(failed)} of {len(chk.rows)} checks passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""pointlens's 3D Gaussian renderer against Mitsuba 3's volumetric primitives.

Run through scripts/gaussians-vs-mitsuba (it makes the virtual environment
and finds a libLLVM for Dr.Jit). The same 3DGS scene and camera go to

* pointlens `render --method pinhole` (R = 0) and `--method accum` (R > 0):
  EWA splats with the reference rasterizer's 0.3 px² dilation, evaluated at
  pixel centres, sorted by centre depth; per lens point the composite is
  decoded from sRGB and the lens points averaged in linear light (EXR);
* Mitsuba 3's `ellipsoids` shape (the PLY read as 3DGS: exp scales, sigmoid
  opacity, quaternion rot_0 = w, SH reordered to [k][channel]) with the
  `volprim_rf_basic` integrator and a `perspective` (R = 0) or `thinlens`
  sensor: each Gaussian evaluated at its peak along the ray, ordered by the
  ray's entry into its 3σ shell; the integrator decodes each ray's composite
  from sRGB (`srgb_primitives`, default true) before the film averages the
  samples, so its output is linear light like pointlens's.

Printed and written to OUT/results.json: PSNR (dB, linear RGB clamped to
[0, 1]) and mean absolute difference, render times, orientation and
field-of-view checks, Mitsuba's noise (two half renders), Mitsuba with one
ray per pixel centre (pointlens's sampling), the effect of averaging encoded
instead of decoded values, and (unless --no-explain) a per-factor account of
the R = 0 difference by an independent NumPy model of both renderers (it
also measures how often Mitsuba's float32 ray-ellipsoid intersection picks
the wrong first Gaussian from the camera). PNGs (sRGB) of every image and of
the scaled |difference|.
"""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "mitsuba"))
import splat_scene  # noqa: E402

# --------------------------------------------------------------------------
# Small helpers


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def srgb_to_linear(c):
    """src/image_io.rs srgb_to_linear, elementwise (values above 1 follow
    the same curve; negatives clamp to 0)."""
    c = np.maximum(np.asarray(c, np.float64), 0.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c):
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1.0 / 2.4) - 0.055)


def psnr(a, b):
    """PSNR in dB over linear RGB clamped to [0, 1]."""
    m = float(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2))
    return float("inf") if m == 0 else 10.0 * np.log10(1.0 / m)


def mad(a, b):
    """Mean absolute difference over linear RGB (not clamped)."""
    return float(np.mean(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


# --------------------------------------------------------------------------
# The 3DGS PLY: read (any byte order or ASCII), write Mitsuba's layout

PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply_vertices(path):
    """(dict name -> float64 array, property names in order) of the first
    element of a PLY file, which must be `vertex` with scalar properties."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        fmt, count, props, in_vertex, seen_element = None, None, [], False, False
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: PLY header without end_header")
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                if not seen_element:
                    if words[1] != "vertex":
                        raise ValueError(f"{path}: first element is {words[1]}, not vertex")
                    count, in_vertex, seen_element = int(words[2]), True, True
                else:
                    in_vertex = False
            elif words[0] == "property" and in_vertex:
                if words[1] == "list":
                    raise ValueError(f"{path}: list property in vertex element")
                if words[1] not in PLY_TYPES:
                    raise ValueError(f"{path}: unknown PLY type {words[1]}")
                props.append((words[2], PLY_TYPES[words[1]]))
        if count is None or not props:
            raise ValueError(f"{path}: no vertex element")
        names = [n for n, _ in props]
        if fmt == "ascii":
            rows = np.loadtxt(f, dtype=np.float64, max_rows=count, ndmin=2)
            if rows.shape != (count, len(props)):
                raise ValueError(f"{path}: ASCII vertex data is {rows.shape}, want {(count, len(props))}")
            return {n: rows[:, i] for i, n in enumerate(names)}, names
        order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
        if order is None:
            raise ValueError(f"{path}: unknown PLY format {fmt}")
        dtype = np.dtype([(n, order + t) for n, t in props])
        data = np.frombuffer(f.read(dtype.itemsize * count), dtype=dtype)
        if len(data) != count:
            raise ValueError(f"{path}: truncated ({len(data)} of {count} vertices)")
        return {n: data[n].astype(np.float64) for n in names}, names


class Scene:
    """A 3DGS scene with the reference code's activations."""

    def __init__(self, path):
        v, names = read_ply_vertices(path)
        need = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
        missing = [n for n in need if n not in v]
        if missing:
            raise ValueError(f"{path}: not a 3DGS PLY (missing {', '.join(missing)})")
        n_rest = sum(1 for n in names if n.startswith("f_rest_"))
        if n_rest not in (0, 9, 24, 45):
            raise ValueError(f"{path}: {n_rest} f_rest_* properties (want 0, 9, 24 or 45)")
        self.path = path
        self.raw = v
        self.n_rest = n_rest
        self.count = len(v["x"])
        self.degree = {0: 0, 9: 1, 24: 2, 45: 3}[n_rest]
        k = (self.degree + 1) ** 2
        self.pos = np.stack([v["x"], v["y"], v["z"]], 1)
        sh = np.zeros((self.count, k, 3))
        for c in range(3):
            sh[:, 0, c] = v[f"f_dc_{c}"]
            for j in range(1, k):
                # channel-major: f_rest_{c*(k-1) + j-1}
                sh[:, j, c] = v[f"f_rest_{c * (k - 1) + j - 1}"]
        self.sh = sh
        self.opacity = 1.0 / (1.0 + np.exp(-v["opacity"]))
        self.scale = np.exp(np.stack([v["scale_0"], v["scale_1"], v["scale_2"]], 1))
        q = np.stack([v["rot_0"], v["rot_1"], v["rot_2"], v["rot_3"]], 1)
        q /= np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-30)
        w, x, y, z = q.T
        r = np.empty((self.count, 3, 3))
        r[:, 0, 0] = 1 - 2 * (y * y + z * z)
        r[:, 0, 1] = 2 * (x * y - w * z)
        r[:, 0, 2] = 2 * (x * z + w * y)
        r[:, 1, 0] = 2 * (x * y + w * z)
        r[:, 1, 1] = 1 - 2 * (x * x + z * z)
        r[:, 1, 2] = 2 * (y * z - w * x)
        r[:, 2, 0] = 2 * (x * z - w * y)
        r[:, 2, 1] = 2 * (y * z + w * x)
        r[:, 2, 2] = 1 - 2 * (x * x + y * y)
        self.rot = r
        m = r * self.scale[:, None, :]
        self.cov = m @ m.transpose(0, 2, 1)
        mi_ = r / self.scale[:, None, :]
        self.cov_inv = mi_ @ mi_.transpose(0, 2, 1)

    def write_mitsuba_ply(self, path):
        """Mitsuba's ellipsoids reader wants exactly: x y z nx ny nz, then
        f_dc_0..2 f_rest_* opacity, then scale_0..2 rot_0..3, all float32
        (it reads each record as floats). The stored (pre-activation)
        values are copied; normals are zeros where the input has none."""
        v = self.raw
        names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        names += [f"f_rest_{i}" for i in range(self.n_rest)]
        names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
        cols = [v.get(n, np.zeros(self.count)) for n in names]
        data = np.stack(cols, 1).astype("<f4")
        header = "ply\nformat binary_little_endian 1.0\n"
        header += f"element vertex {self.count}\n"
        header += "".join(f"property float {n}\n" for n in names)
        header += "end_header\n"
        tmp = path + ".tmp"
        with open(tmp, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(data.tobytes())
        os.replace(tmp, path)


# --------------------------------------------------------------------------
# SH evaluation (the reference code's constants; Dr.Jit's sh_eval agrees)

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
         -1.0925484305920792, 0.5462742152960396]
SH_C3 = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
         0.3731763325901154, -0.4570457994644658, 1.445305721320277,
         -0.5900435899266435]


def sh_basis(d, degree):
    """(n, (degree+1)²) basis values for unit directions d (n, 3)."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    out = [np.full_like(x, SH_C0)]
    if degree > 0:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree > 1:
        xx, yy, zz = x * x, y * y, z * z
        out += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2 * zz - xx - yy),
                SH_C2[3] * x * z, SH_C2[4] * (xx - yy)]
    if degree > 2:
        out += [SH_C3[0] * y * (3 * xx - yy), SH_C3[1] * x * y * z,
                SH_C3[2] * y * (4 * zz - xx - yy), SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
                SH_C3[4] * x * (4 * zz - xx - yy), SH_C3[5] * z * (xx - yy),
                SH_C3[6] * x * (xx - 3 * yy)]
    return np.stack(out, 1)


def sh_color(sh, degree, d):
    """Colours (n, 3) of coefficients sh (n, k, 3) along unit d (n, 3):
    + 0.5, clamped at 0 (as both renderers do)."""
    b = sh_basis(d, degree)
    return np.maximum(np.einsum("nk,nkc->nc", b, sh) + 0.5, 0.0)


# --------------------------------------------------------------------------
# The camera (pointlens's: DESIGN §2)


class Camera:
    def __init__(self, cam):
        self.cam = cam
        self.w, self.h = int(cam["width"]), int(cam["height"])
        self.eye = np.asarray(cam["eye"], np.float64)
        fwd = np.asarray(cam["target"], np.float64) - self.eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, np.asarray(cam["up"], np.float64))
        right /= np.linalg.norm(right)
        self.right, self.up, self.fwd = right, np.cross(right, fwd), fwd
        self.f = (self.h / 2.0) / np.tan(np.radians(cam["fovy_deg"]) / 2.0)
        self.wmat = np.stack([self.right, self.up, self.fwd], 0)  # world -> eye rows


# --------------------------------------------------------------------------
# An independent NumPy model of both renderers at R = 0 (pixel centres)


TILE = 16


class PairModel:
    """Every (pixel, Gaussian) pair that either renderer's model can
    composite, with what each model needs of it. Pixel centres at +0.5
    (pointlens's and Mitsuba's film alike)."""

    def __init__(self, scene, camera, jitter=(0.0, 0.0), chunk_pairs=3_000_000):
        c, s = camera, scene
        self.jitter = jitter
        e = (s.pos - c.eye) @ c.wmat.T  # eye coordinates: x right, y up, z forward
        keep = e[:, 2] > 0.2  # pointlens's cull (Mitsuba's near clip is 0.01; none lie between here)
        tan_x, tan_y = c.w / (2 * c.f), c.h / (2 * c.f)
        z = e[:, 2]
        tx = np.clip(e[:, 0] / z, -1.3 * tan_x, 1.3 * tan_x) * z
        ty = np.clip(e[:, 1] / z, -1.3 * tan_y, 1.3 * tan_y) * z
        j = np.zeros((s.count, 2, 3))
        j[:, 0, 0] = c.f / z
        j[:, 0, 2] = -c.f * tx / (z * z)
        j[:, 1, 1] = -c.f / z
        j[:, 1, 2] = c.f * ty / (z * z)
        t = j @ c.wmat  # (n, 2, 3)
        cov2 = t @ s.cov @ t.transpose(0, 2, 1)
        self.centre = np.stack([c.w / 2 + c.f * e[:, 0] / z, c.h / 2 - c.f * e[:, 1] / z], 1)
        # Eye depth, float64 (pointlens's is float32: depths closer than
        # its resolution may sort the other way there).
        self.depth = z
        self.conic, self.tiles = {}, {}
        grid = ((c.w + TILE - 1) // TILE, (c.h + TILE - 1) // TILE)
        at = self.centre - 0.5
        lam_cand = None
        for dil in (0.3, 0.0):
            a, b, cc = cov2[:, 0, 0] + dil, cov2[:, 0, 1], cov2[:, 1, 1] + dil
            det = a * cc - b * b
            ok = det > 0
            det_s = np.where(ok, det, 1.0)
            self.conic[dil] = np.stack([cc / det_s, -b / det_s, a / det_s], 1)
            mid = 0.5 * (a + cc)
            lam = mid + np.sqrt(np.maximum(mid * mid - det, 0.1))
            if lam_cand is None:
                lam_cand = lam
            r = np.ceil(3.0 * np.sqrt(lam))
            lo = lambda v, n: np.clip((v - r) / TILE, 0, n).astype(np.int64)
            hi = lambda v, n: np.clip((v + r + TILE - 1) / TILE, 0, n).astype(np.int64)
            tl = np.stack([lo(at[:, 0], grid[0]), hi(at[:, 0], grid[0]),
                           lo(at[:, 1], grid[1]), hi(at[:, 1], grid[1])], 1)
            empty = (tl[:, 1] - tl[:, 0]) * (tl[:, 3] - tl[:, 2]) == 0
            tl[empty | ~ok] = 0
            self.tiles[dil] = tl
        # Candidate pixels: a box that holds the α ≥ 1/255 region of the
        # dilated splat (≤ 3.33 σ) and the 3σ shell's outline, with margin.
        rc = np.ceil(3.5 * np.sqrt(lam_cand) + 2.0)
        x0 = np.clip(np.floor(self.centre[:, 0] - rc), 0, c.w).astype(np.int64)
        x1 = np.clip(np.ceil(self.centre[:, 0] + rc), 0, c.w).astype(np.int64)
        y0 = np.clip(np.floor(self.centre[:, 1] - rc), 0, c.h).astype(np.int64)
        y1 = np.clip(np.ceil(self.centre[:, 1] + rc), 0, c.h).astype(np.int64)
        gsel = np.nonzero(keep & (x1 > x0) & (y1 > y0))[0]
        a = s.cov_inv
        self.a6 = np.stack([a[:, 0, 0], a[:, 1, 1], a[:, 2, 2], a[:, 0, 1], a[:, 0, 2], a[:, 1, 2]], 1)
        oc = c.eye - s.pos
        self.ao = np.einsum("nij,nj->ni", a, oc)
        self.oao = np.einsum("ni,ni->n", oc, self.ao)
        # SH colour along camera -> centre (pointlens), per Gaussian.
        dc = s.pos - c.eye
        dc /= np.linalg.norm(dc, axis=1, keepdims=True)
        self.col_centre = sh_color(s.sh, s.degree, dc)
        parts = []
        counts = (x1 - x0)[gsel] * (y1 - y0)[gsel]
        start = 0
        while start < len(gsel):
            cum = np.cumsum(counts[start:])
            stop = start + max(1, int(np.searchsorted(cum, chunk_pairs)))
            parts.append(self._pairs(s, c, gsel[start:stop], x0, x1, y0, y1))
            start = stop
        self.p = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        self.camera = c

    def _pairs(self, s, c, g, x0, x1, y0, y1):
        w = (x1 - x0)[g]
        n = w * (y1 - y0)[g]
        idx = np.repeat(g, n)
        local = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        ww = np.repeat(w, n)
        px = x0[idx] + local % ww
        py = y0[idx] + local // ww
        del local, ww
        cx, cy = px + 0.5 + self.jitter[0], py + 0.5 + self.jitter[1]
        # The ray from the eye through the sample (Mitsuba's, unit length);
        # its closest approach to the Gaussian in Mahalanobis terms (m2),
        # from per-Gaussian A = Σ⁻¹, A·o and oᵀA·o (o = eye − centre).
        ux, uy = (cx - c.w / 2) / c.f, -(cy - c.h / 2) / c.f
        d = ux[:, None] * c.right + uy[:, None] * c.up + c.fwd
        d /= np.sqrt(1.0 + ux * ux + uy * uy)[:, None]
        a6 = self.a6[idx]
        dad = (a6[:, 0] * d[:, 0] ** 2 + a6[:, 1] * d[:, 1] ** 2 + a6[:, 2] * d[:, 2] ** 2
               + 2 * (a6[:, 3] * d[:, 0] * d[:, 1] + a6[:, 4] * d[:, 0] * d[:, 2] + a6[:, 5] * d[:, 1] * d[:, 2]))
        del a6
        oad = np.einsum("ni,ni->n", d, self.ao[idx])
        m2 = np.maximum(self.oao[idx] - oad * oad / dad, 0.0)
        o = s.opacity[idx]
        keep = m2 <= 9.0
        powers, intiles = {}, {}
        for dil in (0.3, 0.0):
            dx = self.centre[idx, 0] - cx
            dy = self.centre[idx, 1] - cy
            k = self.conic[dil][idx]
            powers[dil] = -0.5 * (k[:, 0] * dx * dx + k[:, 2] * dy * dy) - k[:, 1] * dx * dy
            tl = self.tiles[dil][idx]
            tx_, ty_ = px // TILE, py // TILE
            intiles[dil] = (tx_ >= tl[:, 0]) & (tx_ < tl[:, 1]) & (ty_ >= tl[:, 2]) & (ty_ < tl[:, 3])
            # Keep what any model can composite.
            keep |= (o * np.exp(powers[dil]) >= 1.0 / 255.0) & intiles[dil]
        out = {"g": idx[keep].astype(np.int32), "pix": (py * c.w + px)[keep].astype(np.int64), "m2": m2[keep]}
        for dil in (0.3, 0.0):
            out[f"power{dil}"] = powers[dil][keep]
            out[f"intile{dil}"] = intiles[dil][keep]
        dad, oad, d = dad[keep], oad[keep], d[keep]
        out["t_peak"] = -oad / dad
        out["t_entry"] = out["t_peak"] - np.sqrt(np.maximum(9.0 - out["m2"], 0.0) / dad)
        out["col_ray"] = sh_color(s.sh[out["g"]], s.degree, d).astype(np.float32)
        return out

    def render(self, scene, dil=0.3, evaluation="ewa", support="tiles", clamp=0.99,
               order="depth", stop="pointlens", first_hit=None):
        """One model's image (linear, H×W×3) and the most Gaussians any
        pixel composited. Arguments name each model choice:
        pointlens's first, Mitsuba's in brackets:
        dil 0.3 [0]; evaluation ewa (at the pixel centre, SH along camera ->
        centre) [peak: the 3D Gaussian at its peak along the ray, SH along
        the ray]; support tiles (the splat's tiles, α ≥ 1/255) [shell: the
        ray hits the 3σ ellipsoid, no α floor]; clamp 0.99 [0.9999]; order
        depth (centre eye depth, ties by index) [shell: entry into the 3σ
        shell, a hit within 1e-4 of the last one lost]; stop pointlens (the
        Gaussian that would take T under 1e-4 ends the pixel, unadded)
        [mitsuba: after the one that takes T to 0.01 or less].

        first_hit (with order and support "shell"): per pixel the Gaussian
        Mitsuba's ray_intersect reports first from the camera and its entry
        t (−1 / inf: none): that one first, then only the shells entered
        more than 1e-4 beyond it, as Mitsuba's re-spawned ray sees them."""
        p, c = self.p, self.camera
        o = scene.opacity[p["g"]]
        if evaluation == "ewa":
            dens = np.exp(np.minimum(p[f"power{dil}"], 0.0))
            valid_pow = p[f"power{dil}"] <= 0.0
            col = self.col_centre[p["g"]]
        else:
            # the peak along the ray; a dilation folds in as it would on
            # screen: not modelled (dil must be 0 here)
            if dil != 0.0:
                raise ValueError("peak evaluation has no dilation")
            dens = np.exp(-0.5 * p["m2"])
            valid_pow = np.ones(len(dens), bool)
            col = p["col_ray"].astype(np.float64)
        alpha = np.minimum(clamp, o * dens)
        if support == "tiles":
            on = p[f"intile{dil}"] & valid_pow & (alpha >= 1.0 / 255.0)
        else:
            on = (p["m2"] <= 9.0) & (p["t_entry"] > 0)
        pix, g = p["pix"][on], p["g"][on]
        alpha, col = alpha[on], col[on]
        if order == "depth":
            key = self.depth[g]
        else:
            # Outside the shell (support=tiles) the peak's t stands in.
            key = np.where(p["m2"][on] <= 9.0, p["t_entry"][on], p["t_peak"][on])
        if first_hit is not None:
            g0, t0 = first_hit
            after = key > t0[pix] + 1e-4
            pix, g, alpha, col, key = pix[after], g[after], alpha[after], col[after], key[after]
            # The first hit's own pair (if the model holds it).
            n_g = scene.count
            comb = p["pix"] * n_g + p["g"]
            order_c = np.argsort(comb)
            want_pix = np.nonzero(g0 >= 0)[0]
            want = want_pix * n_g + g0[want_pix]
            at = np.searchsorted(comb, want, sorter=order_c)
            at = np.minimum(at, len(comb) - 1)
            found = comb[order_c[at]] == want
            k = order_c[at[found]]
            pix = np.concatenate([pix, p["pix"][k]])
            g = np.concatenate([g, p["g"][k]])
            a_all = np.minimum(clamp, scene.opacity[p["g"][k]] * np.exp(-0.5 * p["m2"][k]))
            alpha = np.concatenate([alpha, a_all])
            col = np.concatenate([col, p["col_ray"][k].astype(np.float64)])
            key = np.concatenate([key, t0[want_pix[found]]])
            # Pixels Mitsuba saw nothing in composite nothing.
            seen = g0[pix] >= 0
            pix, g, alpha, col, key = pix[seen], g[seen], alpha[seen], col[seen], key[seen]
        srt = np.lexsort((g, key, pix))
        pix, g, alpha, col, key = pix[srt], g[srt], alpha[srt], col[srt], key[srt]
        first = np.ones(len(pix), bool)
        first[1:] = pix[1:] != pix[:-1]
        if order == "shell":
            # Mitsuba re-spawns the ray 1e-4 past each hit (back faces
            # culled): an entry within 1e-4 of the previous is never hit.
            lost = np.zeros(len(pix), bool)
            lost[1:] = (~first[1:]) & (key[1:] - key[:-1] <= 1e-4)
            keep = ~lost
            pix, alpha, col, first = pix[keep], alpha[keep], col[keep], first[keep]
        seg = np.cumsum(first) - 1
        la = np.log1p(-alpha)
        cum = np.cumsum(la)
        seg_start = np.nonzero(first)[0]
        before = cum[seg_start][seg]  # cum at the first element of the segment
        log_after = cum - before + la[seg_start][seg]
        t_after = np.exp(log_after)
        t_before = t_after / (1.0 - alpha)
        if stop == "pointlens":
            ended = t_after < 1e-4
            n_end = np.cumsum(ended)
            n_end_seg = n_end - (n_end[seg_start] - ended[seg_start])[seg]
            use = n_end_seg == 0
        else:
            ended = t_after <= 0.01
            n_end = np.cumsum(ended)
            inc = n_end - (n_end[seg_start] - ended[seg_start])[seg]
            use = (inc - ended) == 0  # none ended before this one
        contrib = (alpha * t_before)[:, None] * col
        img = np.zeros((c.h * c.w, 3))
        np.add.at(img, pix[use], contrib[use])
        depth_max = int(np.bincount(pix[use], minlength=c.h * c.w).max()) if use.any() else 0
        return srgb_to_linear(img).reshape(c.h, c.w, 3), depth_max


# --------------------------------------------------------------------------
# pointlens


def run_pointlens(args, scene_path, out_exr, method, aperture, samples=None, ssaa=None, timings=None):
    cmd = [args.pointlens, "-q", "render", scene_path, "-o", out_exr, "--method", method] + camera_flags(args, aperture)
    if samples:
        cmd += ["--samples", str(samples)]
    if ssaa:
        cmd += ["--ssaa", str(ssaa)]
    if args.device:
        cmd += ["--device", args.device]
    if timings:
        cmd += ["--timings-json", timings]
    started = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if r.returncode != 0:
        raise SystemExit(f"gaussians-vs-mitsuba: pointlens failed ({' '.join(cmd)}): {r.stderr.strip()}")
    frame_ms = None
    if timings and os.path.exists(timings):
        with open(timings) as f:
            frame_ms = json.load(f).get("frame_wall_ms")
    return seconds, frame_ms


def camera_flags(args, aperture):
    return ["--width", str(args.width), "--height", str(args.height), "--eye", args.eye,
            "--target", args.target, "--up", args.up, "--fovy-deg", str(args.fovy_deg),
            "--aperture-radius", str(aperture), "--focus-distance", str(args.focus_distance)]


def print_camera(args, scene_path, aperture):
    """The camera pointlens resolves (its --print-camera JSON; that command
    also renders, here a pinhole image to a scratch file)."""
    scratch = os.path.join(args.out, "print_camera_scratch.exr")
    cmd = [args.pointlens, "-q", "render", scene_path, "-o", scratch, "--method", "pinhole",
           "--print-camera"] + camera_flags(args, aperture)
    if args.device:
        cmd += ["--device", args.device]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if os.path.exists(scratch):
        os.remove(scratch)
    if r.returncode != 0:
        raise SystemExit(f"gaussians-vs-mitsuba: pointlens --print-camera failed: {r.stderr.strip()}")
    return json.loads(r.stdout)


# --------------------------------------------------------------------------
# Mitsuba


def mitsuba_scene(mi, ply, cam, srgb_primitives=True):
    # The sensor as the splat comparison builds it (perspective or
    # thinlens, box-filtered float film).
    sensor = splat_scene.sensor_dict(mi, cam)
    return mi.load_dict({
        "type": "scene",
        # max_depth -1: no cap on the Gaussians a ray composites (the
        # default 64 would be a third stopping rule); the integrator still
        # stops a ray once its transmittance is 0.01 or less.
        "integrator": {"type": "volprim_rf_basic", "max_depth": -1, "srgb_primitives": srgb_primitives},
        "gaussians": {"type": "ellipsoids", "filename": ply},
        "sensor": sensor,
    })


def mitsuba_render(mi, dr, scene, spp, seed):
    started = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    arr = np.array(img, dtype=np.float64)
    return arr, time.perf_counter() - started


def mitsuba_two_halves(mi, dr, scene, spp):
    """The spp image as the mean of two independent halves (seeds 0 and 1),
    the seconds of both, and the noise of the whole estimated from their
    difference: MSE(whole vs its expectation) ≈ MSE(a − b) / 4."""
    half = max(1, spp // 2)
    a, ta = mitsuba_render(mi, dr, scene, half, 0)
    b, tb = mitsuba_render(mi, dr, scene, half, 1)
    noise_mse = float(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2)) / 4.0
    return 0.5 * (a + b), ta + tb, (10 * np.log10(1 / noise_mse) if noise_mse > 0 else float("inf"))


def mitsuba_pixel_centres(mi, dr, scene, cam):
    """Mitsuba's integrator on one ray through each pixel centre (the lens
    centre), as pointlens samples: (linear image, first hit, seconds). The
    first hit is what scene.ray_intersect reports from the camera: per
    pixel the Gaussian (−1: none) and its entry's distance from the eye
    (Mitsuba's rays start at the near clip plane, 0.01 ahead)."""
    w, h = int(cam["width"]), int(cam["height"])
    started = time.perf_counter()
    sensor, integrator = scene.sensors()[0], scene.integrator()
    idx = dr.arange(mi.UInt32, w * h)
    pos = mi.Point2f((mi.Float(idx % w) + 0.5) / w, (mi.Float(idx // w) + 0.5) / h)
    ray, _ = sensor.sample_ray(0.0, 0.0, pos, mi.Point2f(0.5, 0.5))
    sampler = sensor.sampler().clone()
    sampler.seed(0, w * h)
    res = integrator.sample(dr.ADMode.Primal, scene, sampler, ray, None, None, mi.Bool(True))
    img = np.array(res[0], dtype=np.float64)
    img = img.reshape(3, -1).T if img.shape[0] == 3 else img.reshape(-1, 3)
    seconds = time.perf_counter() - started
    si = scene.ray_intersect(ray)
    valid = np.array(si.is_valid())
    prim = np.where(valid, np.array(si.prim_index).astype(np.int64), -1)
    pts = np.array(si.p, dtype=np.float64)
    pts = pts.reshape(3, -1).T if pts.shape[0] == 3 else pts
    dirs = np.array(ray.d, dtype=np.float64)
    dirs = dirs.reshape(3, -1).T if dirs.shape[0] == 3 else dirs
    t_eye = np.einsum("ni,ni->n", pts - np.asarray(cam["eye"], np.float64), dirs)
    t_eye = np.where(valid, t_eye, np.inf)
    return img.reshape(h, w, 3), (prim, t_eye), seconds


def first_hit_check(pm, first_hit):
    """Mitsuba's first hit from the camera against the exact first entry
    into a 3σ shell (the NumPy model, float64): the share of hit pixels
    where it is the same Gaussian and the error of its entry distance."""
    g0, t0 = first_hit
    p = pm.p
    on = (p["m2"] <= 9.0) & (p["t_entry"] > 0)
    pix, t, g = p["pix"][on], p["t_entry"][on], p["g"][on]
    o = np.lexsort((t, pix))
    pix, t, g = pix[o], t[o], g[o]
    first = np.ones(len(pix), bool)
    first[1:] = pix[1:] != pix[:-1]
    n = len(g0)
    t_ex = np.full(n, np.inf)
    g_ex = np.full(n, -1)
    t_ex[pix[first]], g_ex[pix[first]] = t[first], g[first]
    both = (g0 >= 0) & (g_ex >= 0)
    same = both & (g0 == g_ex)
    err = np.abs(t0[both] - t_ex[both])
    return {"pixels_hit_mitsuba": int((g0 >= 0).sum()), "pixels_hit_exact": int((g_ex >= 0).sum()),
            "same_gaussian_share": float(same.sum() / max(both.sum(), 1)),
            "entry_error_median": float(np.median(err)) if len(err) else 0.0,
            "entry_error_p90": float(np.percentile(err, 90)) if len(err) else 0.0,
            "entry_spacing_median": float(np.median(np.diff(t)[~first[1:]])) if len(t) > 1 else 0.0}


# --------------------------------------------------------------------------
# Images


def read_exr(mi, path):
    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def write_png(mi, path, linear):
    enc = (linear_to_srgb(linear) * 255.0 + 0.5).astype(np.uint8)
    mi.Bitmap(np.ascontiguousarray(enc), pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def write_diff_png(mi, path, a, b, scale):
    """|a − b| in linear light × scale, shown as is (no sRGB curve)."""
    d = np.clip(np.abs(a - b) * scale, 0, 1)
    mi.Bitmap(np.ascontiguousarray((d * 255 + 0.5).astype(np.uint8)),
              pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def write_panel(mi, path, a, b, scale):
    """pointlens | Mitsuba | |difference| × scale, side by side."""
    gap = np.ones((a.shape[0], 4, 3))
    d = np.clip(np.abs(a - b) * scale, 0, 1)
    row = np.concatenate([linear_to_srgb(a), gap, linear_to_srgb(b), gap, d], 1)
    mi.Bitmap(np.ascontiguousarray((row * 255 + 0.5).astype(np.uint8)),
              pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def resample(img, scale=1.0, dx=0.0, dy=0.0):
    """img magnified by `scale` about the image centre and shifted by
    (dx, dy) px, bilinear (for the field-of-view and alignment check)."""
    h, w = img.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    sx = (xs - w / 2 - dx) / scale + w / 2 - 0.5
    sy = (ys - h / 2 - dy) / scale + h / 2 - 0.5
    x0 = np.clip(np.floor(sx).astype(int), 0, w - 2)
    y0 = np.clip(np.floor(sy).astype(int), 0, h - 2)
    fx = np.clip(sx - x0, 0, 1)[..., None]
    fy = np.clip(sy - y0, 0, 1)[..., None]
    return ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1])
            + fy * ((1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]))


def geometry_checks(pl, mi_img):
    """PSNR of pointlens against Mitsuba as is, mirrored in x or y, scaled
    by ±1 % and ±3 % and shifted by half a pixel: the best should be the
    image as is (orientation and field of view agree)."""
    out = {"as_is": psnr(pl, mi_img), "mirrored_x": psnr(pl, mi_img[:, ::-1]),
           "mirrored_y": psnr(pl, mi_img[::-1])}
    for s in (0.97, 0.99, 1.01, 1.03):
        out[f"scaled_{s:g}"] = psnr(pl, resample(mi_img, scale=s))
    for dx, dy in ((0.5, 0), (-0.5, 0), (0, 0.5), (0, -0.5)):
        out[f"shift_{dx:+g}_{dy:+g}"] = psnr(pl, resample(mi_img, dx=dx, dy=dy))
    return out


# --------------------------------------------------------------------------


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pointlens", required=True)
    ap.add_argument("--scene", help="a 3DGS PLY (default: pointlens synth --gaussians N)")
    ap.add_argument("--gaussians", type=int, default=20000)
    ap.add_argument("--out", default="/tmp/gaussians-vs-mitsuba")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--eye", default="0,0,3.2")
    ap.add_argument("--target", default="0,0,0")
    ap.add_argument("--up", default="0,1,0")
    ap.add_argument("--fovy-deg", type=float, default=40.0)
    ap.add_argument("--aperture-radius", type=float, default=0.1)
    ap.add_argument("--focus-distance", type=float, default=2.6,
                    help="eye depth in focus (default 2.6: the middle spheres sharp, the wall at 3.5 blurred)")
    ap.add_argument("--samples", type=int, default=256, help="pointlens accum lens samples")
    ap.add_argument("--spp", type=int, default=64, help="Mitsuba samples per pixel at R = 0")
    ap.add_argument("--lens-spp", type=int, default=256, help="Mitsuba samples per pixel with the lens")
    ap.add_argument("--device", default="llvmpipe", help="pointlens --device ('' for its default)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--diff-scale", type=float, default=8.0)
    ap.add_argument("--no-explain", action="store_true", help="skip the NumPy model's per-factor account")
    ap.add_argument("--model-subpixels", type=int, default=3,
                    help="the Mitsuba model is also averaged over K×K sub-pixel positions, as Mitsuba's box "
                         "filter averages the pixel (0: skip)")
    ap.add_argument("--no-encoded", action="store_true",
                    help="skip the Mitsuba renders that average encoded values (srgb_primitives false)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    for n in ("width", "height", "samples", "spp", "lens_spp", "gaussians"):
        if getattr(args, n) < 1:
            raise SystemExit(f"gaussians-vs-mitsuba: --{n.replace('_', '-')} must be positive")
    if args.aperture_radius <= 0:
        raise SystemExit("gaussians-vs-mitsuba: --aperture-radius must be positive (R = 0 is always compared)")

    import mitsuba as mi
    mi.set_variant(args.variant)
    import drjit as dr

    results = {"mitsuba_version": mi.__version__, "drjit_version": dr.__version__, "variant": args.variant,
               "args": vars(args)}

    # 1. The scene.
    if args.scene:
        scene_path = os.path.abspath(args.scene)
        if not os.path.isfile(scene_path):
            raise SystemExit(f"gaussians-vs-mitsuba: no scene file at {scene_path}")
    else:
        scene_path = os.path.join(args.out, f"synth_{args.gaussians}.ply")
        r = subprocess.run([args.pointlens, "-q", "synth", "--gaussians", str(args.gaussians), "-o", scene_path],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit(f"gaussians-vs-mitsuba: pointlens synth failed: {r.stderr.strip()}")
    scene = Scene(scene_path)
    mi_ply = os.path.join(args.out, "scene_mitsuba.ply")
    scene.write_mitsuba_ply(mi_ply)
    results["scene"] = {"path": scene_path, "gaussians": scene.count, "sh_degree": scene.degree}
    log(f"scene: {scene.count} Gaussians, SH degree {scene.degree} ({scene_path})")

    cams = {"pinhole": print_camera(args, scene_path, 0.0), "lens": print_camera(args, scene_path, args.aperture_radius)}
    results["cameras"] = cams
    cam0 = Camera(cams["pinhole"])
    coc_note = None
    e = (scene.pos - cam0.eye) @ cam0.wmat.T
    zs = e[:, 2][e[:, 2] > 0.2]
    if len(zs):
        s_, r_ = args.focus_distance, args.aperture_radius
        coc = 2 * r_ * cam0.f * np.abs(zs - s_) / (zs * s_)
        coc_note = {"depth_min": float(zs.min()), "depth_max": float(zs.max()), "coc_px_max": float(coc.max())}
        results["lens_coc"] = coc_note

    out = lambda name: os.path.join(args.out, name)

    # 2. pointlens.
    log("pointlens: pinhole, pinhole --ssaa 4, accum")
    t_pin, f_pin = run_pointlens(args, scene_path, out("pointlens_pinhole.exr"), "pinhole", 0.0,
                                 timings=out("pointlens_pinhole.json"))
    t_ss, f_ss = run_pointlens(args, scene_path, out("pointlens_pinhole_ssaa4.exr"), "pinhole", 0.0, ssaa=4,
                               timings=out("pointlens_pinhole_ssaa4.json"))
    t_acc, f_acc = run_pointlens(args, scene_path, out("pointlens_accum.exr"), "accum", args.aperture_radius,
                                 samples=args.samples, timings=out("pointlens_accum.json"))
    pl0 = read_exr(mi, out("pointlens_pinhole.exr"))
    pl0_ss = read_exr(mi, out("pointlens_pinhole_ssaa4.exr"))
    pl1 = read_exr(mi, out("pointlens_accum.exr"))

    # 3. Mitsuba.
    log(f"mitsuba {mi.__version__} ({args.variant}): R = 0 at {args.spp} spp, thin lens at {args.lens_spp} spp")
    started = time.perf_counter()
    s0 = mitsuba_scene(mi, mi_ply, cams["pinhole"])
    s1 = mitsuba_scene(mi, mi_ply, cams["lens"])
    t_load = time.perf_counter() - started
    mi0, t_mi0, noise0 = mitsuba_two_halves(mi, dr, s0, args.spp)
    mi1, t_mi1, noise1 = mitsuba_two_halves(mi, dr, s1, args.lens_spp)
    mi0c, first_hit, t_mi0c = mitsuba_pixel_centres(mi, dr, s0, cams["pinhole"])
    mi.Bitmap(mi0.astype(np.float32)).write(out("mitsuba_pinhole.exr"))
    mi.Bitmap(mi0c.astype(np.float32)).write(out("mitsuba_pinhole_centres.exr"))
    mi.Bitmap(mi1.astype(np.float32)).write(out("mitsuba_lens.exr"))

    # 4. Colour: Mitsuba's default decodes each ray's composite (linear
    # averaging, as pointlens). Its srgb_primitives=false output is the
    # encoded average; decoded after averaging it shows what encoded
    # averaging would do.
    enc = {}
    if not args.no_encoded:
        log("mitsuba: srgb_primitives=false (average of encoded values), R = 0 and thin lens")
        e0, t_e0, _ = mitsuba_two_halves(mi, dr, mitsuba_scene(mi, mi_ply, cams["pinhole"], False), args.spp)
        e1, t_e1, _ = mitsuba_two_halves(mi, dr, mitsuba_scene(mi, mi_ply, cams["lens"], False), args.lens_spp)
        e0, e1 = srgb_to_linear(e0), srgb_to_linear(e1)
        enc = {
            "pinhole": {"psnr_vs_pointlens": psnr(pl0, e0), "mad_vs_pointlens": mad(pl0, e0),
                        "psnr_vs_mitsuba_default": psnr(mi0, e0), "mean_linear": float(e0.mean()),
                        "render_s": t_e0},
            "lens": {"psnr_vs_pointlens": psnr(pl1, e1), "mad_vs_pointlens": mad(pl1, e1),
                     "psnr_vs_mitsuba_default": psnr(mi1, e1), "mean_linear": float(e1.mean()),
                     "render_s": t_e1},
        }
        results["encoded_averaging"] = enc

    # 5. Numbers.
    res = {
        "pinhole": {
            "psnr": psnr(pl0, mi0), "mad": mad(pl0, mi0),
            "psnr_pointlens_ssaa4": psnr(pl0_ss, mi0), "mad_pointlens_ssaa4": mad(pl0_ss, mi0),
            "psnr_pointlens_ssaa4_vs_ssaa1": psnr(pl0_ss, pl0),
            # One ray per pixel centre, as pointlens samples (no noise).
            "psnr_mitsuba_pixel_centres": psnr(pl0, mi0c), "mad_mitsuba_pixel_centres": mad(pl0, mi0c),
            "psnr_mitsuba_centres_vs_64spp": psnr(mi0c, mi0),
            "mitsuba_noise_psnr": noise0, "mean_pointlens": float(pl0.mean()), "mean_mitsuba": float(mi0.mean()),
            # Were Mitsuba's output encoded, decoding it would bring it
            # closer to pointlens; it is already linear, so this is worse.
            "psnr_if_mitsuba_decoded_again": psnr(pl0, srgb_to_linear(mi0)),
            "geometry": geometry_checks(pl0, mi0),
        },
        "lens": {
            "psnr": psnr(pl1, mi1), "mad": mad(pl1, mi1), "mitsuba_noise_psnr": noise1,
            "mean_pointlens": float(pl1.mean()), "mean_mitsuba": float(mi1.mean()),
            "psnr_vs_own_pinhole": {"pointlens": psnr(pl1, pl0), "mitsuba": psnr(mi1, mi0)},
            "geometry": geometry_checks(pl1, mi1),
        },
        "times_s": {
            "pointlens_pinhole_process": t_pin, "pointlens_pinhole_frame": (f_pin or 0) / 1000,
            "pointlens_pinhole_ssaa4_process": t_ss, "pointlens_pinhole_ssaa4_frame": (f_ss or 0) / 1000,
            "pointlens_accum_process": t_acc, "pointlens_accum_frame": (f_acc or 0) / 1000,
            "mitsuba_scene_load": t_load, "mitsuba_pinhole_render": t_mi0, "mitsuba_lens_render": t_mi1,
            "mitsuba_pinhole_centres_render": t_mi0c,
        },
    }
    results.update(res)

    # 6. The NumPy model's account of the R = 0 difference.
    if not args.no_explain:
        log("model: the R = 0 difference factor by factor (NumPy)")
        started = time.perf_counter()
        pm = PairModel(scene, cam0)
        pl_opts = dict(dil=0.3, evaluation="ewa", support="tiles", clamp=0.99, order="depth", stop="pointlens")
        steps = [
            ("dilation 0.3 px² -> none", dict(dil=0.0)),
            ("EWA at the pixel centre -> 3D peak along the ray (SH along the ray)", dict(evaluation="peak")),
            ("support: splat tiles, alpha >= 1/255 -> the ray's 3-sigma shell, no floor", dict(support="shell")),
            ("alpha clamp 0.99 -> 0.9999", dict(clamp=0.9999)),
            ("order: centre depth -> entry into the 3-sigma shell", dict(order="shell")),
            ("stop: T < 1e-4 (unadded) -> T <= 0.01 (added)", dict(stop="mitsuba")),
        ]
        model_pl, depth_pl = pm.render(scene, **pl_opts)
        rows = []
        cur = dict(pl_opts)
        prev = model_pl
        model_pl_nodil = None
        for name, change in steps:
            alone = dict(pl_opts, **change)
            base = model_pl
            if change.get("evaluation") == "peak":
                # The peak has no screen-space dilation: against the
                # undilated pointlens model.
                alone["dil"] = 0.0
                base = model_pl_nodil
            img_alone, _ = pm.render(scene, **alone)
            if change.get("dil") == 0.0:
                model_pl_nodil = img_alone
            cur.update(change)
            img_cum, depth_cum = pm.render(scene, **cur)
            rows.append({"factor": name,
                         "alone_psnr_vs_model_pointlens": psnr(base, img_alone),
                         "alone_mad": mad(base, img_alone),
                         "cumulative_psnr_vs_mitsuba_centres": psnr(img_cum, mi0c),
                         "step_psnr": psnr(prev, img_cum), "step_mad": mad(prev, img_cum)})
            prev = img_cum
        model_mi = prev
        mi_opts = cur
        # Mitsuba's float32 ray-ellipsoid intersection from the camera: its
        # first hit, then the exact model from there on.
        model_fh, _ = pm.render(scene, first_hit=first_hit, **mi_opts)
        rows.append({"factor": "Mitsuba's own first hit from the camera (float32 ray-ellipsoid intersection)",
                     "alone_psnr_vs_model_pointlens": float("nan"), "alone_mad": float("nan"),
                     "cumulative_psnr_vs_mitsuba_centres": psnr(model_fh, mi0c),
                     "step_psnr": psnr(model_mi, model_fh), "step_mad": mad(model_mi, model_fh)})
        sub = None
        if args.model_subpixels > 0:
            k = args.model_subpixels
            acc = np.zeros_like(model_mi)
            for i in range(k):
                for j in range(k):
                    pj = PairModel(scene, cam0, jitter=((i + 0.5) / k - 0.5, (j + 0.5) / k - 0.5))
                    acc += pj.render(scene, **mi_opts)[0]
            acc /= k * k
            sub = {"k": k, "psnr": psnr(acc, mi0), "mad": mad(acc, mi0), "psnr_vs_pointlens": psnr(acc, pl0)}
        write_png(mi, out("model_pointlens.png"), model_pl)
        write_png(mi, out("model_mitsuba.png"), model_mi)
        results["model"] = {
            "pairs": int(len(pm.p["pix"])),
            "seconds": time.perf_counter() - started,
            "model_pointlens_vs_real_pointlens": {"psnr": psnr(model_pl, pl0), "mad": mad(model_pl, pl0),
                                                  "max_abs": float(np.abs(model_pl - pl0).max())},
            "model_mitsuba_vs_real_mitsuba": {"psnr": psnr(model_mi, mi0), "mad": mad(model_mi, mi0)},
            "model_mitsuba_vs_mitsuba_centres": {"psnr": psnr(model_mi, mi0c), "mad": mad(model_mi, mi0c),
                                                 "pixels_over_1e-3": int((np.abs(model_mi - mi0c).max(2) > 1e-3).sum())},
            "model_mitsuba_first_hit_vs_mitsuba_centres": {
                "psnr": psnr(model_fh, mi0c), "mad": mad(model_fh, mi0c),
                "pixels_over_1e-3": int((np.abs(model_fh - mi0c).max(2) > 1e-3).sum())},
            "first_hit": first_hit_check(pm, first_hit),
            "model_pointlens_pixels_over_1e-4": int((np.abs(model_pl - pl0).max(2) > 1e-4).sum()),
            "model_mitsuba_subpixels_vs_real_mitsuba": sub,
            "model_pointlens_vs_model_mitsuba": {"psnr": psnr(model_pl, model_mi), "mad": mad(model_pl, model_mi)},
            "most_gaussians_composited_in_a_pixel": {"pointlens_model": depth_pl, "mitsuba_model": depth_cum},
            "steps": rows,
        }

    # 7. Images.
    write_png(mi, out("pinhole_pointlens.png"), pl0)
    write_png(mi, out("pinhole_mitsuba.png"), mi0)
    write_diff_png(mi, out("pinhole_diff.png"), pl0, mi0, args.diff_scale)
    write_panel(mi, out("pinhole_panel.png"), pl0, mi0, args.diff_scale)
    write_png(mi, out("lens_pointlens.png"), pl1)
    write_png(mi, out("lens_mitsuba.png"), mi1)
    write_diff_png(mi, out("lens_diff.png"), pl1, mi1, args.diff_scale)
    write_panel(mi, out("lens_panel.png"), pl1, mi1, args.diff_scale)

    with open(out("results.json"), "w") as f:
        json.dump(results, f, indent=2)

    # 8. Summary.
    r0, r1, t = results["pinhole"], results["lens"], results["times_s"]
    L = []
    L.append(f"gaussians-vs-mitsuba: {scene.count} Gaussians (SH degree {scene.degree}), {args.width}x{args.height}, "
             f"eye {args.eye} target {args.target} up {args.up}, fovy {args.fovy_deg:g} deg")
    L.append(f"  Mitsuba {mi.__version__} ({args.variant}): ellipsoids + volprim_rf_basic (max_depth -1, "
             f"srgb_primitives true), perspective / thinlens, box filter; pointlens --device {args.device or '(default)'}")
    L.append(f"  R = 0:  PSNR {r0['psnr']:.2f} dB, mean |diff| {r0['mad']:.5f}  "
             f"(pointlens pinhole vs Mitsuba {args.spp} spp; Mitsuba's noise alone ~{r0['mitsuba_noise_psnr']:.1f} dB)")
    L.append(f"          Mitsuba one ray per pixel centre (pointlens's sampling, no noise): {r0['psnr_mitsuba_pixel_centres']:.2f} dB, "
             f"mean |diff| {r0['mad_mitsuba_pixel_centres']:.5f}; pointlens --ssaa 4 vs Mitsuba {args.spp} spp: "
             f"{r0['psnr_pointlens_ssaa4']:.2f} dB")
    g0 = r0["geometry"]
    L.append(f"          orientation / field of view: as is {g0['as_is']:.2f} dB; mirrored x {g0['mirrored_x']:.2f}, "
             f"y {g0['mirrored_y']:.2f}; scaled 0.97/0.99/1.01/1.03: {g0['scaled_0.97']:.2f}/{g0['scaled_0.99']:.2f}/"
             f"{g0['scaled_1.01']:.2f}/{g0['scaled_1.03']:.2f}; shifted +-0.5 px in x {g0['shift_+0.5_+0']:.2f}/"
             f"{g0['shift_-0.5_+0']:.2f}, in y {g0['shift_+0_+0.5']:.2f}/{g0['shift_+0_-0.5']:.2f} "
             f"(bilinear resampling smooths, which alone raises PSNR a little)")
    L.append(f"          colour: Mitsuba's output decoded once more (as if it were encoded): "
             f"{r0['psnr_if_mitsuba_decoded_again']:.2f} dB; mean linear value pointlens {r0['mean_pointlens']:.4f}, "
             f"Mitsuba {r0['mean_mitsuba']:.4f}")
    lens_coc = f", CoC up to {coc_note['coc_px_max']:.1f} px" if coc_note else ""
    L.append(f"  R = {args.aperture_radius:g}, S = {args.focus_distance:g}{lens_coc}:  PSNR {r1['psnr']:.2f} dB, "
             f"mean |diff| {r1['mad']:.5f}  (accum {args.samples} lens samples vs Mitsuba {args.lens_spp} spp; "
             f"Mitsuba's noise alone ~{r1['mitsuba_noise_psnr']:.1f} dB)")
    L.append(f"          blur vs own pinhole: pointlens {r1['psnr_vs_own_pinhole']['pointlens']:.2f} dB, "
             f"Mitsuba {r1['psnr_vs_own_pinhole']['mitsuba']:.2f} dB; mirrored x {r1['geometry']['mirrored_x']:.2f} dB")
    if enc:
        L.append(f"  encoded averaging (Mitsuba srgb_primitives false: the pixel mean of encoded values, decoded after): "
                 f"vs pointlens R = 0 {enc['pinhole']['psnr_vs_pointlens']:.2f} dB, lens {enc['lens']['psnr_vs_pointlens']:.2f} dB; "
                 f"vs Mitsuba's default (same samples) R = 0 {enc['pinhole']['psnr_vs_mitsuba_default']:.2f} dB, "
                 f"lens {enc['lens']['psnr_vs_mitsuba_default']:.2f} dB")
    L.append(f"  times: pointlens pinhole {t['pointlens_pinhole_process']:.2f} s (frame {t['pointlens_pinhole_frame']:.2f} s), "
             f"accum {args.samples} {t['pointlens_accum_process']:.1f} s (frame {t['pointlens_accum_frame']:.1f} s); "
             f"Mitsuba R = 0 {args.spp} spp {t['mitsuba_pinhole_render']:.1f} s, lens {args.lens_spp} spp "
             f"{t['mitsuba_lens_render']:.1f} s (each two half renders, first-use kernel compiles included), "
             f"1 ray/pixel {t['mitsuba_pinhole_centres_render']:.1f} s")
    if "model" in results:
        m = results["model"]
        fh = m["first_hit"]
        L.append(f"  NumPy model of both (R = 0, pixel centres; {m['pairs']} pixel-Gaussian pairs, {m['seconds']:.0f} s):")
        L.append(f"    pointlens model vs pointlens: {m['model_pointlens_vs_real_pointlens']['psnr']:.1f} dB, "
                 f"max |diff| {m['model_pointlens_vs_real_pointlens']['max_abs']:.1e}, "
                 f"{m['model_pointlens_pixels_over_1e-4']} pixels over 1e-4")
        L.append(f"    Mitsuba model vs Mitsuba (1 ray/pixel centre): {m['model_mitsuba_vs_mitsuba_centres']['psnr']:.2f} dB "
                 f"({m['model_mitsuba_vs_mitsuba_centres']['pixels_over_1e-3']} pixels over 1e-3); with Mitsuba's own "
                 f"first hit: {m['model_mitsuba_first_hit_vs_mitsuba_centres']['psnr']:.2f} dB "
                 f"({m['model_mitsuba_first_hit_vs_mitsuba_centres']['pixels_over_1e-3']} pixels)")
        L.append(f"    Mitsuba's first hit from the camera is the first shell entered in {100 * fh['same_gaussian_share']:.1f} % "
                 f"of pixels; entry distance error median {fh['entry_error_median']:.4f}, p90 {fh['entry_error_p90']:.4f} "
                 f"(median spacing of entries along a ray {fh['entry_spacing_median']:.4f})")
        sub = m["model_mitsuba_subpixels_vs_real_mitsuba"]
        if sub:
            L.append(f"    Mitsuba model over {sub['k']}x{sub['k']} sub-pixel positions vs Mitsuba {args.spp} spp: "
                     f"{sub['psnr']:.2f} dB")
        L.append("    the R = 0 difference, one model choice at a time (pointlens's -> Mitsuba's):")
        L.append(f"      {'factor':<78} {'alone':>8} {'step':>8} {'cum. vs Mitsuba':>16}")
        for row in m["steps"]:
            alone = row["alone_psnr_vs_model_pointlens"]
            alone_s = "     -  " if alone != alone else f"{alone:6.2f}dB"
            L.append(f"      {row['factor']:<78} {alone_s} {row['step_psnr']:6.2f}dB "
                     f"{row['cumulative_psnr_vs_mitsuba_centres']:14.2f}dB")
        L.append("      (alone: the pointlens model with only that choice changed, vs the pointlens model (the peak: "
                 "both undilated); step: each cumulative model vs the one before; cum.: vs Mitsuba, 1 ray/pixel centre)")
    L.append(f"  images: {args.out}/{{pinhole,lens}}_{{pointlens,mitsuba,diff,panel}}.png "
             f"(diff = |pointlens - Mitsuba| x {args.diff_scale:g}, linear); results.json")
    lines = L
    text = "\n".join(lines)
    print(text)
    with open(out("summary.txt"), "w") as f:
        f.write(text + "\n")


if __name__ == "__main__":
    try:
        main()
    except (ValueError, RuntimeError, OSError) as e:
        # One line, not a traceback: a bad scene file, a Mitsuba load error.
        msg = " ".join(str(e).split())
        print(f"gaussians-vs-mitsuba: {msg}", file=sys.stderr)
        sys.exit(2)

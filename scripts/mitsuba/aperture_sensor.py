"""A thin-lens Mitsuba 3 sensor with the shaped aperture of
docs/decisions/aperture-shape.md (the contract): an independent reference
for pointlens's blades, curvature, rotation, anamorphic squeeze, aperture
image and cat's eye.

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    import aperture_sensor
    aperture_sensor.register()            # mi.register_sensor("aperture_thinlens", ...)
    sensor = mi.load_dict({"type": "aperture_thinlens", "fov": 40, "fov_axis": "y",
                           "aperture_radius": 0.2, "focus_distance": 1.0,
                           "aperture_blades": 6, "aperture_rotation_deg": 30, ...})

Written for the JIT variants (llvm_ad_rgb, checked; cuda_ad_rgb, not run
here; register() refuses scalar variants): `sample_ray` is
traced once per render over all samples, so everything below is branch-free
Dr.Jit code (fixed iteration counts, `dr.select`, `dr.gather`, one symbolic
`dr.while_loop`).

Projection: identical to Mitsuba's `thinlens`
---------------------------------------------
Same parameters and defaults: `fov` + `fov_axis` (x, y, diagonal, smaller,
larger) or `focal_length` (35 mm equivalent), as Mitsuba's parse_fov;
`to_world` (no scale allowed); `near_clip` (0.01), `far_clip` (1e4),
`focus_distance` (default far_clip), `aperture_radius` R (0 becomes
Dr.Jit's epsilon, as thinlens). The film position goes through Mitsuba's own
`perspective_projection` (film size, crop size and offset); the ray leaves
the aperture point a = (a.x, a.y, 0) of camera space toward the point of the
focal plane z = focus_distance that the film position maps to, its origin
moved to the near plane and its maxt to the far plane, with thinlens's ray
differentials. Only the aperture point differs: thinlens takes
R·square_to_uniform_disk_concentric(aperture_sample); this sensor takes
a = R·(−u.x, −u.y) with u drawn from the shaped aperture.

Pixel axes and Mitsuba's camera axes
------------------------------------
The document's u is in image pixel axes (x right, y down). Mitsuba's camera
space (look_at) has +x = up × forward, that is to the left of the image,
+y up and +z forward; perspective_projection scales camera x and y by −0.5
on the way to film coordinates, so film (0, 0), the top-left corner, is
camera (+x, +y). Hence pixel x = −camera x and pixel y = −camera y, and the
lens position u (pixel axes) is the camera-space aperture point
R·(−u.x, −u.y). Check: a point P at depth z seen through aperture point a
lands on the film where the ray from a through P meets the focal plane S;
its image position (camera x/z, y/z) is P/z + a·(1/S − 1/z), i.e. moved
along +a (camera) = +u (pixels) behind the focus plane (z > S) and along −u
in front of it, as the document states (q + sign(z − S)·c/2·u).
aperture_check.py verifies this by rendering: a 5-blade aperture images
with a corner up, turned 90° with the corner to the left, and in front of
the focus plane turned by 180°.

Sampling the lens position (density ∝ T(u)·C(u; p), every ray weight 1)
-----------------------------------------------------------------------
T(u) = B(w) with w = rotate_cw(θ, squeeze(u)), a linear map, so u is drawn
as w ~ B(w)·[|w| ≤ 1] and u = lens_of(w) (squeeze⁻¹ ∘ rotate⁻¹): a linear
map keeps a density proportional. w is drawn

* round: Mitsuba's concentric disk map (exact; with no cat's eye and no
  squeeze this is exactly thinlens's lens distribution);
* blades (N, curvature C): sector k = ⌊ξ₁·N⌋ (equal areas by symmetry);
  within it the angle δ from the sector's middle with density ∝ ρ(δ)²
  (the polar area element), by solving H(δ) = (2ξ₁' − 1)·H(π/N) with
  H(δ) = a²·tan δ + 2aC·atanh(sin δ) + C²·δ, a = (1 − C)·cos(π/N) (the
  integral of ρ² = (a/cos δ + C)²): 12 Newton steps from δ = π/N (H is odd
  and convex for δ > 0, so the steps decrease monotonically onto the root;
  the residual measured over 2·10⁵ samples for N = 3…16, C = 0…1 is
  below 1e-6 rad, float32 rounding); then radius ρ(δ)·√ξ₂. Exact up to
  float32 rounding;
* image (W×H pixels over [−1, 1]², B as the document's pixel lookup): B is
  piecewise constant on the pixel cells, so the sampler is a tabulated
  piecewise-constant 2D distribution over cells (each pixel split into
  k×k equal sub-cells, k such that the table has ≥ 512 cells a side where
  it fits in 4M cells), a cell's weight its pixel's value times the EXACT
  area of the cell inside the unit circle (closed form), rows by inverse
  CDF (binary search with dr.gather), then the column in the row's
  conditional CDF, the position in the cell from the two reused fractions.
  A point of a rim cell that falls outside the circle is redrawn in the
  same cell with hashed randoms, 8 rounds, then falls back to the cell's
  point nearest the centre. Residual: only rim cells, the fallback's mass
  is at most max_f f(1 − f)^8 ≈ 4.1 % of one sub-cell's area per rim cell
  (for a fully open circle and 512 cells a side, about 2000 rim cells:
  < 1e-3 of the mass), moved by less than one sub-cell's diagonal (2√2/512
  of the lens radius); the fractions reused from a float32 ξ keep
  24 − log2(cells a side) bits inside a cell (≥ 12 bits).

The cat's eye (S > 0) needs a second, per-pixel constraint: the pixel is
the film pixel holding the sample, ⌊position_sample·crop_size + crop_offset⌋
(its centre p = that + 0.5, d = (p − (W/2, H/2))/|(W/2, H/2)| with W×H the
film's full size). The allowed set is the lens L = {|u| ≤ 1} ∩
{|u + 2S·d| ≤ 1}: centred at −S·d, half-extent 1 − S|d| along d and
√(1 − S²|d|²) across. Rejection sampling with one of two proposals per
pixel, whichever accepts more often:
  (a) u ~ T (the sampler above), accepted if u ∈ L: acceptance ∫_L T / ∫T;
  (b) u uniform in L's bounding box (aligned with d), accepted if u ∈ L
      and ξ₃·T_max < T(u) (T_max: the largest transmission in the circle,
      1 but for an image): acceptance ∫_L T / (|box|·T_max);
so (a) where ∫T ≤ |box|·T_max, else (b); either is exactly ∝ T·C once
accepted. Up to `rounds` attempts (default 64): the first with the
sampler's aperture sample (keeping its stratification), the others with
fresh randoms (the Tiny Encryption Algorithm hashing the aperture and film
samples and a per-lane counter) in a symbolic `dr.while_loop` that runs
only while some lane of a packet has not accepted, so a frame costs a few
attempts, not 64. A lane with no acceptance falls back to u = −S·d, the
centre of L (weight 1, as every ray). Residual: the fallback share
(1 − acceptance)^rounds of a pixel's rays, moved to L's centre. For the
round aperture the chosen proposal accepts ≥ 2/3 (the lens fills 2/3 to
π/4 of its box), so it is nil; for blades and images it depends on how
much of L the shape covers: aperture_check.py measures 0 for 6 blades at
S = 1 next to the frame's edge and 1e-6 for a sparse star image at S = 1
near a corner. Where
∫T·C(·; p) = 0 (blades or an image at S near 1 near a corner, the lens L
falling outside the shape) the document defines no density: every ray of
that pixel falls back to u = −S·d. Property `fallback` = "drop" gives
fallen-back rays weight 0 instead, to measure the residual.
A box reconstruction filter (as splat_scene.py uses) makes "the pixel of
the sample" exactly the pixel it is added to; with a wider filter a sample
also reaches neighbours that have their own cat's eye (an approximation
the document does not cover). A sample whose float32 film position rounds
onto the next pixel's edge (about 1e-7 of them) takes that pixel's d.

Properties beyond thinlens's: `aperture_blades` (0 = round, 3..16),
`aperture_rotation_deg`, `blade_curvature` (0..1), `anamorphic_ratio`
(> 0), `aperture_image` (a path: grayscale PNG 8/16 bit, or an EXR with one
channel or R = G = B), `cat_eye` (0..1), `rounds` (64), `fallback`
("centre" or "drop").

The aperture image is read with mi.Bitmap: a PNG must be one channel (Y)
of 8 or 16 bits, value / 255 or / 65535 (no sRGB decoding: the raw value is
the linear transmission); an EXR one channel, or RGB/RGBA with R = G = B
(alpha ignored, as pointlens), clamped to [0, 1]; NaN refused. The lookup is
the document's: pixel (⌊(w.x + 1)/2·W⌋, ⌊(w.y + 1)/2·H⌋) clamped, row 0 at
the top.

Use in scripts/bench-vs-mitsuba
-------------------------------
`sensor_from_camera(camera_json, film_dict=None, sample_count=1,
base_dir=None)` turns pointlens's `render --print-camera` JSON (a dict, a
JSON string or a path) into the Mitsuba sensor dict: the camera as
splat_scene.sensor_dict builds it (fov with fov_axis "y", look_at(eye,
target, up), far_clip 1e6, aperture_radius, focus_distance, an
`independent` sampler) with type "aperture_thinlens" and the aperture
fields `aperture_blades`, `aperture_rotation_deg`, `blade_curvature`,
`anamorphic_ratio`, `aperture_image`, `cat_eye` (each absent or null: the
document's default); aperture_radius 0 gives Mitsuba's `perspective`.
bench.py calls `aperture_sensor.register()` once after
`mi.set_variant(...)` (the sensor is a Python plugin: it exists only in the
process that registered it) and passes

    sensor=aperture_sensor.sensor_from_camera(cam, film_dict)

to splat_scene.build_scene in place of `sensor_dict(mi, cam)` (film_dict:
the hdrfilm dict of sensor_dict, box filter, rgb, float32; None builds that
dict from the camera's width and height). A relative `aperture_image` is taken relative
to `base_dir` (default: the current directory, where pointlens resolved
it). With all aperture fields absent the sensor draws the same lens
distribution as `thinlens` (aperture_check.py compares the two renders).
The sample count of the render is mi.render's `spp`, as today; a path
integrator with max_depth 1 and a box filter as splat_scene.py sets up is
what the cat's eye's per-pixel constraint assumes (see above).
"""

import json
import math
import os

import numpy as np

NAME = "aperture_thinlens"
MAX_BLADES = 16
# Newton steps of the blade angle (see the module's docstring).
BLADE_NEWTON_STEPS = 12
# Redraws of a rim cell's point that fell outside the circle.
IMAGE_RIM_ROUNDS = 8
# The image table: at least this many cells a side where it fits ...
IMAGE_TABLE_SIDE = 512
# ... in at most this many cells.
IMAGE_TABLE_MAX_CELLS = 1 << 22


# ---------------------------------------------------------------------------
# The document's definition in numpy (float64): tables for the sensor, and
# predictions for aperture_check.py.
# ---------------------------------------------------------------------------


def read_aperture_image(path):
    """The transmission in [0, 1] (H×W float64, row 0 at the top) of a
    grayscale PNG (8 or 16 bits) or a one-channel / grey EXR, read with
    mi.Bitmap (any variant)."""
    import mitsuba as mi

    path = os.fspath(path)
    bmp = mi.Bitmap(path)
    arr = np.array(bmp, copy=True)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    channels = arr.shape[2]
    comp = bmp.component_format()
    is_exr = path.lower().endswith(".exr")
    if is_exr:
        arr = arr.astype(np.float64)
        if channels in (3, 4):
            if not (np.array_equal(arr[..., 0], arr[..., 1]) and np.array_equal(arr[..., 1], arr[..., 2])):
                raise ValueError(f"{path}: an EXR aperture image must be grey (R = G = B) or one channel")
        elif channels != 1:
            raise ValueError(f"{path}: {channels} channels; an EXR aperture image has one, or R = G = B")
        t = arr[..., 0]
        if np.isnan(t).any():
            raise ValueError(f"{path}: has a NaN pixel")
        t = np.clip(t, 0.0, 1.0)
    else:
        if channels != 1:
            raise ValueError(f"{path}: {channels} channels; a PNG aperture image is grayscale (one channel)")
        if comp == mi.Struct.Type.UInt8:
            t = arr[..., 0].astype(np.float64) / 255.0
        elif comp == mi.Struct.Type.UInt16:
            t = arr[..., 0].astype(np.float64) / 65535.0
        else:
            raise ValueError(f"{path}: component format {comp}; a PNG aperture image has 8 or 16 bits")
    if t.size == 0:
        raise ValueError(f"{path}: empty")
    return t


def _quadrant_area(x, y):
    """Signed area of {0 ≤ s ≤ x, 0 ≤ t ≤ y, s² + t² ≤ 1} (orientation by
    the signs of x and y)."""
    sx, sy = np.sign(x), np.sign(y)
    x = np.minimum(np.abs(x), 1.0)
    y = np.minimum(np.abs(y), 1.0)
    xs = np.sqrt(np.maximum(1.0 - y * y, 0.0))

    def g(t):
        return 0.5 * (t * np.sqrt(np.maximum(1.0 - t * t, 0.0)) + np.arcsin(np.clip(t, -1.0, 1.0)))

    inside = x * x + y * y <= 1.0
    area = np.where(inside, x * y, y * xs + g(x) - g(np.minimum(xs, x)))
    return sx * sy * area


def rect_disk_area(x0, x1, y0, y1):
    """Exact area of the rectangle [x0, x1] × [y0, y1] inside the unit
    disk (vectorised)."""
    return (_quadrant_area(x1, y1) - _quadrant_area(x0, y1) - _quadrant_area(x1, y0)
            + _quadrant_area(x0, y0))


class ApertureShape:
    """T(u) and C(u; p) of docs/decisions/aperture-shape.md, in numpy."""

    def __init__(self, blades=0, rotation_deg=0.0, curvature=0.0, ratio=1.0, image=None, cat_eye=0.0):
        blades = int(blades)
        if blades != 0 and not 3 <= blades <= MAX_BLADES:
            raise ValueError(f"aperture_blades must be 0 (round) or 3 to {MAX_BLADES}, got {blades}")
        if not 0.0 <= curvature <= 1.0:
            raise ValueError(f"blade_curvature must be in [0, 1], got {curvature}")
        if not (math.isfinite(ratio) and ratio > 0.0):
            raise ValueError(f"anamorphic_ratio must be a finite number > 0, got {ratio}")
        if not math.isfinite(rotation_deg):
            raise ValueError(f"aperture_rotation_deg must be finite, got {rotation_deg}")
        if not 0.0 <= cat_eye <= 1.0:
            raise ValueError(f"cat_eye must be in [0, 1], got {cat_eye}")
        if blades and image is not None:
            raise ValueError("aperture_blades and aperture_image exclude each other")
        self.blades = blades
        self.rotation_deg = float(rotation_deg)
        self.curvature = float(curvature)
        self.ratio = float(ratio)
        self.cat_eye = float(cat_eye)
        if image is not None and not isinstance(image, np.ndarray):
            image = read_aperture_image(image)
        self.image = None if image is None else np.clip(np.asarray(image, np.float64), 0.0, 1.0)
        if self.image is not None and self.image_area_w() <= 0.0:
            raise ValueError("the aperture image lets no light through the lens's circle")

    # -- the maps between u and w -------------------------------------------
    def base_of(self, u):
        """w of lens positions u (…×2, pixel axes)."""
        u = np.asarray(u, np.float64)
        if self.ratio >= 1.0:
            sx, sy = self.ratio * u[..., 0], u[..., 1]
        else:
            sx, sy = u[..., 0], u[..., 1] / self.ratio
        th = math.radians(self.rotation_deg)
        c, s = math.cos(th), math.sin(th)
        return np.stack([c * sx - s * sy, s * sx + c * sy], axis=-1)

    def lens_of(self, w):
        """u of base points w (the inverse of base_of)."""
        w = np.asarray(w, np.float64)
        th = math.radians(self.rotation_deg)
        c, s = math.cos(th), math.sin(th)
        sx = c * w[..., 0] + s * w[..., 1]
        sy = -s * w[..., 0] + c * w[..., 1]
        if self.ratio >= 1.0:
            return np.stack([sx / self.ratio, sy], axis=-1)
        return np.stack([sx, sy * self.ratio], axis=-1)

    def jacobian(self):
        """|dw/du|: areas in u are areas in w divided by this."""
        return max(self.ratio, 1.0 / self.ratio)

    # -- the base shape ------------------------------------------------------
    def blade_radius(self, phi):
        n = self.blades
        sector = 2.0 * math.pi / n
        delta = np.mod(phi - math.pi / 2.0, sector) - sector / 2.0
        return (1.0 - self.curvature) * math.cos(math.pi / n) / np.cos(delta) + self.curvature

    def image_pixel(self, w):
        h, wd = self.image.shape
        i = np.clip(np.floor((w[..., 0] + 1.0) * 0.5 * wd), 0, wd - 1).astype(np.int64)
        j = np.clip(np.floor((w[..., 1] + 1.0) * 0.5 * h), 0, h - 1).astype(np.int64)
        return i, j

    def transmission(self, u):
        """T(u) ∈ [0, 1] for lens positions u (…×2, pixel axes)."""
        w = self.base_of(u)
        r2 = w[..., 0] ** 2 + w[..., 1] ** 2
        if self.image is not None:
            i, j = self.image_pixel(w)
            b = self.image[j, i]
        elif self.blades == 0:
            b = np.ones(r2.shape)
        else:
            rho = self.blade_radius(np.arctan2(-w[..., 1], w[..., 0]))
            b = (r2 <= rho * rho).astype(np.float64)
        return np.where(r2 > 1.0, 0.0, b)

    @staticmethod
    def cat_eye_centre(px, py, width, height, s):
        """−2S·d for film pixel centres (px, py) (already + 0.5)."""
        hx, hy = width / 2.0, height / 2.0
        n = math.hypot(hx, hy)
        return -2.0 * s * (px - hx) / n, -2.0 * s * (py - hy) / n

    # -- areas -----------------------------------------------------------------
    def blade_h(self, delta):
        """H(δ) = ∫₀^δ ρ² (the blades' polar area, per unit ½)."""
        n = self.blades
        a = (1.0 - self.curvature) * math.cos(math.pi / n)
        c = self.curvature
        return a * a * np.tan(delta) + 2.0 * a * c * np.arctanh(np.sin(delta)) + c * c * delta

    def image_table(self):
        """(k, weights Hg×Wg): each image pixel split into k×k sub-cells,
        weight = pixel value × exact area of the sub-cell inside the unit
        circle."""
        h, wd = self.image.shape
        k = max(1, math.ceil(IMAGE_TABLE_SIDE / min(h, wd)))
        k = max(1, min(k, int(math.sqrt(IMAGE_TABLE_MAX_CELLS / (h * wd)))))
        hg, wg = h * k, wd * k
        xe = -1.0 + 2.0 * np.arange(wg + 1) / wg
        ye = -1.0 + 2.0 * np.arange(hg + 1) / hg
        cov = rect_disk_area(xe[None, :-1], xe[None, 1:], ye[:-1, None], ye[1:, None])
        cov = np.maximum(cov, 0.0)
        b = np.repeat(np.repeat(self.image, k, axis=0), k, axis=1)
        return k, b * cov

    def image_area_w(self):
        h, wd = self.image.shape
        xe = -1.0 + 2.0 * np.arange(wd + 1) / wd
        ye = -1.0 + 2.0 * np.arange(h + 1) / h
        cov = np.maximum(rect_disk_area(xe[None, :-1], xe[None, 1:], ye[:-1, None], ye[1:, None]), 0.0)
        return float((self.image * cov).sum())

    def area_u(self):
        """∫T(u) du, exactly (π for the round aperture)."""
        if self.image is not None:
            aw = self.image_area_w()
        elif self.blades == 0:
            aw = math.pi
        else:
            aw = self.blades * float(self.blade_h(math.pi / self.blades))
        return aw / self.jacobian()

    def t_max(self):
        """The largest transmission inside the circle (1 but for an image)."""
        if self.image is None:
            return 1.0
        h, wd = self.image.shape
        xe = -1.0 + 2.0 * np.arange(wd + 1) / wd
        ye = -1.0 + 2.0 * np.arange(h + 1) / h
        cov = rect_disk_area(xe[None, :-1], xe[None, 1:], ye[:-1, None], ye[1:, None])
        return float(self.image[cov > 0.0].max())

    def mean_transmission_in_circle(self):
        """∫B over the unit circle / π (the image's mean inside the circle)."""
        if self.image is not None:
            return self.image_area_w() / math.pi
        return self.area_u() * self.jacobian() / math.pi


# ---------------------------------------------------------------------------
# Mitsuba's parse_fov (src/render/sensor.cpp), so that the fov convention is
# thinlens's exactly.
# ---------------------------------------------------------------------------


def parse_fov(props, aspect):
    has_fov = props.has_property("fov")
    has_fl = props.has_property("focal_length")
    if has_fov and has_fl:
        raise ValueError("Please specify either a focal length ('focal_length') or a field of view ('fov')!")
    if has_fov:
        fov = float(props.get("fov"))
        axis = str(props.get("fov_axis", "x")).lower()
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
    else:
        f = str(props.get("focal_length", "50mm"))
        if f.endswith("mm"):
            f = f[:-2]
        fov = 2.0 * math.degrees(math.atan(math.sqrt(36.0 * 36.0 + 24.0 * 24.0) / (2.0 * float(f))))
        axis = "diagonal"
    if axis == "x":
        result = fov
    elif axis == "y":
        result = math.degrees(2.0 * math.atan(math.tan(0.5 * math.radians(fov)) * aspect))
    elif axis == "diagonal":
        diagonal = 2.0 * math.tan(0.5 * math.radians(fov))
        width = diagonal / math.sqrt(1.0 + 1.0 / (aspect * aspect))
        result = math.degrees(2.0 * math.atan(width * 0.5))
    else:
        raise ValueError("The 'fov_axis' parameter must be set to one of 'smaller', 'larger', 'diagonal', 'x', or 'y'!")
    if result <= 0.0 or result >= 180.0:
        raise ValueError("The horizontal field of view must be in the range [0, 180]!")
    return result


# ---------------------------------------------------------------------------
# The sensor (defined once a variant is set).
# ---------------------------------------------------------------------------

_CLASS = None


def register():
    """Registers the sensor "aperture_thinlens" for the current variant
    (call after mi.set_variant); returns its class."""
    global _CLASS
    import drjit as dr
    import mitsuba as mi

    if not dr.is_jit_v(mi.Float):
        raise RuntimeError(f"{NAME} needs a JIT variant (llvm_ad_rgb, cuda_ad_rgb), not {mi.variant()}")
    if _CLASS is not None and _CLASS.variant == mi.variant():
        mi.register_sensor(NAME, lambda props: _CLASS(props))
        return _CLASS

    Float, UInt32 = mi.Float, mi.UInt32
    Point2f, Point3f, Vector3f = mi.Point2f, mi.Point3f, mi.Vector3f

    def bits(x):
        return dr.reinterpret_array(UInt32, x)

    def to_unit(v):
        # 24 random bits to [0, 1).
        return Float(v >> 8) * (1.0 / 16777216.0)

    class Rng:
        """Fresh randoms per lane: TEA of the lane's aperture and film
        samples and a per-lane counter `k` (a Dr.Jit variable, so that it
        can be the state of a symbolic loop)."""

        def __init__(self, aperture_sample, position_sample):
            a0, a1 = mi.sample_tea_32(bits(aperture_sample.x), bits(aperture_sample.y))
            p0, _ = mi.sample_tea_32(bits(position_sample.x), bits(position_sample.y) ^ UInt32(0x5BD1E995))
            self.s0, self.s1 = a0, a1 ^ p0
            self.k = dr.zeros(UInt32, dr.width(a0))

        def next2(self):
            self.k = self.k + 1
            v0, v1 = mi.sample_tea_32(self.s0, self.s1 + self.k * UInt32(0x9E3779B9), 4)
            return Point2f(to_unit(v0), to_unit(v1))

    class ApertureThinLens(mi.Sensor):
        variant = mi.variant()

        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            film = self.film()
            size = film.size()
            self.film_size = (int(size[0]), int(size[1]))
            crop_size, crop_offset = film.crop_size(), film.crop_offset()
            self.crop_size = (int(crop_size[0]), int(crop_size[1]))
            self.crop_offset = (int(crop_offset[0]), int(crop_offset[1]))
            self.x_fov = parse_fov(props, self.film_size[0] / self.film_size[1])
            self.near_clip = float(props.get("near_clip", 1e-2))
            self.far_clip = float(props.get("far_clip", 1e4))
            self.focus_distance = float(props.get("focus_distance", self.far_clip))
            if self.near_clip <= 0.0:
                raise ValueError("The 'near_clip' parameter must be greater than zero!")
            if self.near_clip >= self.far_clip:
                raise ValueError("The 'near_clip' parameter must be smaller than 'far_clip'.")
            self.aperture_radius = float(props.get("aperture_radius"))
            if self.aperture_radius == 0.0:
                self.aperture_radius = float(dr.epsilon(Float))
            m = np.array(self.m_to_world.matrix, dtype=np.float64).reshape(4, 4)
            if not np.allclose(np.linalg.norm(m[:3, :3], axis=0), 1.0, atol=1e-4):
                raise ValueError("Scale factors in the camera-to-world transformation are not allowed!")

            image = props.get("aperture_image", "")
            self.shape = ApertureShape(
                blades=int(props.get("aperture_blades", 0)),
                rotation_deg=float(props.get("aperture_rotation_deg", 0.0)),
                curvature=float(props.get("blade_curvature", 0.0)),
                ratio=float(props.get("anamorphic_ratio", 1.0)),
                image=str(image) if image else None,
                cat_eye=float(props.get("cat_eye", 0.0)),
            )
            self.rounds = int(props.get("rounds", 64))
            self.fallback = str(props.get("fallback", "centre"))
            if self.fallback not in ("centre", "drop"):
                raise ValueError("fallback must be 'centre' or 'drop'")
            if self.rounds < 1:
                raise ValueError("rounds must be ≥ 1")

            self.camera_to_sample = mi.perspective_projection(
                mi.ScalarVector2i(*self.film_size), mi.ScalarVector2i(*self.crop_size),
                mi.ScalarVector2i(*self.crop_offset), self.x_fov, self.near_clip, self.far_clip)
            self.sample_to_camera = self.camera_to_sample.inverse()
            res = self.crop_size
            o = self.sample_to_camera @ Point3f(0.0, 0.0, 0.0)
            self.dx = Vector3f(self.sample_to_camera @ Point3f(1.0 / res[0], 0.0, 0.0) - o)
            self.dy = Vector3f(self.sample_to_camera @ Point3f(0.0, 1.0 / res[1], 0.0) - o)
            self.m_needs_sample_3 = True
            self._tables()

        # -- tables --------------------------------------------------------------
        def _tables(self):
            sh = self.shape
            self.area_u = sh.area_u()
            self.t_max = sh.t_max()
            th = math.radians(sh.rotation_deg)
            self.rot_c, self.rot_s = math.cos(th), math.sin(th)
            if sh.image is not None:
                h, wd = sh.image.shape
                self.img_w, self.img_h = wd, h
                self.img_t = Float(sh.image.astype(np.float32).ravel())
                k, weights = sh.image_table()
                hg, wg = weights.shape
                self.grid_w, self.grid_h = wg, hg
                rows = weights.sum(axis=1)
                self.row_cdf = Float(_cdf(rows).astype(np.float32))
                cond = np.empty_like(weights)
                for j in range(hg):
                    if rows[j] > 0.0:
                        cond[j] = _cdf(weights[j])
                    else:
                        cond[j] = (np.arange(wg) + 1.0) / wg
                self.col_cdf = Float(cond.astype(np.float32).ravel())

        # -- the base shape in Dr.Jit ---------------------------------------------
        def _lens_of(self, w):
            c, s = self.rot_c, self.rot_s
            sx = c * w.x + s * w.y
            sy = -s * w.x + c * w.y
            a = self.shape.ratio
            if a >= 1.0:
                return Point2f(sx / a, sy)
            return Point2f(sx, sy * a)

        def _base_of(self, u):
            a = self.shape.ratio
            if a >= 1.0:
                sx, sy = a * u.x, u.y
            else:
                sx, sy = u.x, u.y / a
            c, s = self.rot_c, self.rot_s
            return Point2f(c * sx - s * sy, s * sx + c * sy)

        def _transmission(self, u):
            sh = self.shape
            w = self._base_of(u)
            r2 = dr.squared_norm(w)
            if sh.image is not None:
                i = UInt32(dr.clip(dr.floor((w.x + 1.0) * 0.5 * self.img_w), 0, self.img_w - 1))
                j = UInt32(dr.clip(dr.floor((w.y + 1.0) * 0.5 * self.img_h), 0, self.img_h - 1))
                b = dr.gather(Float, self.img_t, j * self.img_w + i)
            elif sh.blades == 0:
                b = Float(1.0)
            else:
                n = sh.blades
                sector = 2.0 * math.pi / n
                phi = dr.atan2(-w.y, w.x) - math.pi / 2.0
                delta = phi - sector * dr.floor(phi / sector) - sector / 2.0
                rho = (1.0 - sh.curvature) * math.cos(math.pi / n) / dr.cos(delta) + sh.curvature
                b = dr.select(r2 <= rho * rho, 1.0, 0.0)
            return dr.select(r2 > 1.0, 0.0, b)

        def _sample_blades(self, xi):
            sh = self.shape
            n = sh.blades
            half = math.pi / n
            c = sh.curvature
            a = (1.0 - c) * math.cos(half)
            hmax = float(sh.blade_h(half))
            k = dr.minimum(UInt32(xi.x * n), n - 1)
            t = 2.0 * (xi.x * n - Float(k)) - 1.0
            target = dr.abs(t) * hmax
            delta = Float(half)
            for _ in range(BLADE_NEWTON_STEPS):
                hval = a * a * dr.tan(delta) + 2.0 * a * c * dr.atanh(dr.sin(delta)) + c * c * delta
                rho = a / dr.cos(delta) + c
                delta = dr.clip(delta - (hval - target) / (rho * rho), 0.0, half)
            delta = dr.select(t < 0.0, -delta, delta)
            rho = a / dr.cos(delta) + c
            phi = math.pi / 2.0 + half + Float(k) * (2.0 * half) + delta
            r = rho * dr.sqrt(xi.y)
            return Point2f(r * dr.cos(phi), -r * dr.sin(phi))

        def _search(self, cdf, base, n, x):
            """The first i in [0, n) with cdf[base + i] > x, and x's
            fraction within that cell."""
            lo, hi = UInt32(0), UInt32(n - 1)
            for _ in range(max(1, math.ceil(math.log2(max(n, 2)))) + 1):
                mid = (lo + hi) >> 1
                pred = dr.gather(Float, cdf, base + mid) > x
                hi = dr.select(pred, mid, hi)
                lo = dr.select(pred, lo, mid + 1)
            c1 = dr.gather(Float, cdf, base + lo)
            c0 = dr.gather(Float, cdf, base + lo - 1, lo > 0)
            f = dr.clip((x - c0) / (c1 - c0), 0.0, 1.0 - 2.0 ** -24)
            return lo, f

        def _sample_image(self, xi, rng):
            wg, hg = self.grid_w, self.grid_h
            row, fy = self._search(self.row_cdf, UInt32(0), hg, xi.y)
            col, fx = self._search(self.col_cdf, row * wg, wg, xi.x)
            cw, ch = 2.0 / wg, 2.0 / hg
            x0 = -1.0 + Float(col) * cw
            y0 = -1.0 + Float(row) * ch
            w = Point2f(x0 + fx * cw, y0 + fy * ch)
            inside = dr.squared_norm(w) <= 1.0
            for _ in range(IMAGE_RIM_ROUNDS):
                z = rng.next2()
                cand = Point2f(x0 + z.x * cw, y0 + z.y * ch)
                take = ~inside & (dr.squared_norm(cand) <= 1.0)
                w = dr.select(take, cand, w)
                inside |= take
            nearest = Point2f(dr.clip(0.0, x0, x0 + cw), dr.clip(0.0, y0, y0 + ch))
            return dr.select(inside, w, nearest)

        def _sample_shape(self, xi, rng):
            """u with density ∝ T(u)."""
            sh = self.shape
            if sh.image is not None:
                w = self._sample_image(xi, rng)
            elif sh.blades == 0:
                w = mi.warp.square_to_uniform_disk_concentric(xi)
            else:
                w = self._sample_blades(xi)
            return self._lens_of(w)

        def sample_lens(self, position_sample, aperture_sample):
            """(u in pixel axes, fell back?) for each lane."""
            rng = Rng(aperture_sample, position_sample)
            s = self.shape.cat_eye
            if s == 0.0:
                return self._sample_shape(aperture_sample, rng), dr.zeros(mi.Bool, dr.width(aperture_sample.x))
            fw, fh = self.film_size
            px = dr.floor(position_sample.x * self.crop_size[0] + self.crop_offset[0]) + 0.5
            py = dr.floor(position_sample.y * self.crop_size[1] + self.crop_offset[1]) + 0.5
            norm = math.hypot(fw / 2.0, fh / 2.0)
            d = Point2f((px - fw / 2.0) / norm, (py - fh / 2.0) / norm)
            dn = dr.norm(d)
            e = Point2f(dr.select(dn > 0.0, d.x / dn, 1.0), dr.select(dn > 0.0, d.y / dn, 0.0))
            eperp = Point2f(-e.y, e.x)
            centre = Point2f(-s * d.x, -s * d.y)
            c2 = Point2f(-2.0 * s * d.x, -2.0 * s * d.y)
            ex = dr.maximum(1.0 - s * dn, 0.0)
            ey = dr.sqrt(dr.maximum(1.0 - s * s * dn * dn, 0.0))
            use_a = self.area_u <= 4.0 * ex * ey * self.t_max

            def attempt(xi, z):
                ua = self._sample_shape(xi, rng)
                ok_a = dr.squared_norm(ua - c2) <= 1.0
                ub = centre + (2.0 * xi.x - 1.0) * ex * e + (2.0 * xi.y - 1.0) * ey * eperp
                ok_b = ((dr.squared_norm(ub) <= 1.0) & (dr.squared_norm(ub - c2) <= 1.0)
                        & (z.x * self.t_max < self._transmission(ub)))
                return dr.select(use_a, ua, ub), dr.select(use_a, ok_a, ok_b)

            # Round 1 with the sampler's own aperture sample (keeps its
            # stratification), the others in a symbolic loop that runs only
            # while some lane of a packet has not accepted yet.
            cand, ok = attempt(aperture_sample, rng.next2())
            u = dr.select(ok, cand, centre)
            n = dr.width(px)
            rounds = dr.full(UInt32, 1, n)

            def cond(u, done, rounds, k):
                return ~done & (rounds < self.rounds)

            def body(u, done, rounds, k):
                rng.k = k
                cand, ok = attempt(rng.next2(), rng.next2())
                return dr.select(ok, cand, u), done | ok, rounds + 1, rng.k

            u, done, _, _ = dr.while_loop((u, ok, rounds, rng.k), cond, body,
                                          labels=("u", "done", "rounds", "k"), label="cat's eye")
            return u, ~done

        # -- rays ------------------------------------------------------------------
        def _ray(self, time, wavelength_sample, position_sample, aperture_sample, active, differential):
            wavelengths, weight = self.sample_wavelengths(
                dr.zeros(mi.SurfaceInteraction3f), wavelength_sample, active)
            near_p = self.sample_to_camera @ Point3f(position_sample.x, position_sample.y, 0.0)
            u, fell_back = self.sample_lens(position_sample, aperture_sample)
            r = self.aperture_radius
            aperture_p = Point3f(-r * u.x, -r * u.y, 0.0)
            f_dist = self.focus_distance / near_p.z
            focus_p = near_p * f_dist
            d = dr.normalize(Vector3f(focus_p - aperture_p))
            to_world = self.m_to_world
            ray = mi.RayDifferential3f() if differential else mi.Ray3f()
            ray.time = time
            ray.wavelengths = wavelengths
            ray.o = to_world @ aperture_p
            ray.d = to_world @ d
            inv_z = dr.rcp(d.z)
            near_t = self.near_clip * inv_z
            far_t = self.far_clip * inv_z
            ray.o = ray.o + ray.d * near_t
            ray.maxt = far_t - near_t
            if differential:
                ray.o_x = ray.o
                ray.o_y = ray.o
                ray.d_x = to_world @ dr.normalize(Vector3f((near_p + self.dx) * f_dist - aperture_p))
                ray.d_y = to_world @ dr.normalize(Vector3f((near_p + self.dy) * f_dist - aperture_p))
                ray.has_differentials = True
            if self.fallback == "drop":
                weight = dr.select(fell_back, 0.0, weight)
            return ray, weight

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return self._ray(time, sample1, sample2, sample3, active, False)

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            return self._ray(time, sample1, sample2, sample3, active, True)

        def bbox(self):
            m = np.array(self.m_to_world.matrix, dtype=np.float64).reshape(4, 4)
            o = mi.ScalarPoint3f(*m[:3, 3])
            return mi.ScalarBoundingBox3f(o, o)

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            sh = self.shape
            return (f"ApertureThinLens[x_fov={self.x_fov}, aperture_radius={self.aperture_radius}, "
                    f"focus_distance={self.focus_distance}, near_clip={self.near_clip}, "
                    f"far_clip={self.far_clip}, blades={sh.blades}, rotation_deg={sh.rotation_deg}, "
                    f"curvature={sh.curvature}, ratio={sh.ratio}, "
                    f"image={None if sh.image is None else sh.image.shape}, cat_eye={sh.cat_eye}]")

    _CLASS = ApertureThinLens
    mi.register_sensor(NAME, lambda props: ApertureThinLens(props))
    return ApertureThinLens


def _cdf(weights):
    """Inclusive cumulative of weights over their sum (float64), exactly 1
    from the last positive weight on."""
    c = np.cumsum(weights, dtype=np.float64)
    total = c[-1]
    c = c / total
    last = np.flatnonzero(weights > 0.0)
    if len(last):
        c[last[-1]:] = 1.0
    return c


# ---------------------------------------------------------------------------
# pointlens's camera → the sensor dict.
# ---------------------------------------------------------------------------

APERTURE_FIELDS = ("aperture_blades", "aperture_rotation_deg", "blade_curvature", "anamorphic_ratio",
                   "aperture_image", "cat_eye")


def sensor_from_camera(camera_json, film_dict=None, sample_count=1, base_dir=None):
    """The Mitsuba sensor dict of pointlens's `render --print-camera` JSON
    (a dict, a JSON string, or a path to a JSON file): as
    splat_scene.sensor_dict, of type "aperture_thinlens" carrying the
    aperture fields present (absent or null: the document's default); with
    aperture_radius 0 or absent, Mitsuba's "perspective" (a pinhole has no
    aperture). `film_dict` is the film (e.g. splat_scene's hdrfilm dict;
    None: that dict at the camera's width × height); a relative
    aperture_image is relative to base_dir (default: the current
    directory)."""
    import mitsuba as mi

    cam = camera_json
    if isinstance(cam, bytes):
        cam = cam.decode()
    if isinstance(cam, os.PathLike) or (isinstance(cam, str) and not cam.lstrip().startswith("{")):
        with open(os.fspath(cam)) as f:
            cam = json.load(f)
    elif isinstance(cam, str):
        cam = json.loads(cam)
    if film_dict is None:
        film_dict = {
            "type": "hdrfilm",
            "width": int(cam["width"]),
            "height": int(cam["height"]),
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
        }
    up = cam.get("up") or [0.0, 1.0, 0.0]
    sensor = {
        "fov": float(cam["fovy_deg"]),
        "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=[float(v) for v in cam["eye"]],
                                                   target=[float(v) for v in cam["target"]],
                                                   up=[float(v) for v in up]),
        "film": film_dict,
        "sampler": {"type": "independent", "sample_count": int(sample_count)},
        "far_clip": 1e6,
    }
    radius = cam.get("aperture_radius")
    if radius is None and cam.get("f_number") is not None:
        raise ValueError("the camera gives f_number, not aperture_radius: print it with `render --print-camera`, "
                         "which resolves the aperture radius")
    if radius is None or float(radius) <= 0.0:
        sensor["type"] = "perspective"
        return sensor
    sensor["type"] = NAME
    sensor["aperture_radius"] = float(radius)
    sensor["focus_distance"] = float(cam["focus_distance"])
    for key in APERTURE_FIELDS:
        value = cam.get(key)
        if value is None:
            continue
        if key == "aperture_blades":
            sensor[key] = int(value)
        elif key == "aperture_image":
            path = os.fspath(value)
            if base_dir is not None and not os.path.isabs(path):
                path = os.path.join(os.fspath(base_dir), path)
            sensor[key] = path
        else:
            sensor[key] = float(value)
    return sensor
